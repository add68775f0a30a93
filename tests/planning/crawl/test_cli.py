"""The crawl CLI refuses bad options by name before it simulates anything."""

from __future__ import annotations

import pytest

from margin_rl.planning.crawl.__main__ import main


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--out", "x", "--robot", "hyq"], "invalid choice: 'hyq'"),
        (["--out", "x", "--load-kg", "-5"], "loads must be >= 0"),
        (["--out", "x", "--hindered-fraction", "0"], "--hindered-fraction must be in (0, 1]"),
        (["--out", "x", "--steps", "0"], "--steps must be >= 1"),
        (["--robot", "anymal_c"], "the following arguments are required: --out"),
    ],
)
def test_bad_options_exit_with_the_reason(argv, message, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
