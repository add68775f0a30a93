"""The wheel is complete: built, installed with --no-deps into a fresh venv, it loads both robots.

An editable install reads the source tree and can hide files missing from the wheel; this test
installs the real wheel where the source tree is invisible and checks the installed namespace.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
import textwrap
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

PROBE = textwrap.dedent(
    """
    import json, sys, importlib.util
    import margin_rl, margin_rl.envs, margin_rl.train, margin_rl.stability, margin_rl.assets
    from margin_rl import load_robot
    robots = {}
    for name in ("anymal_b", "anymal_c"):
        r = load_robot(name)
        robots[name] = {"mass": r.total_mass, "xml": str(r.xml_path), "scene": str(r.scene_path)}
    print(json.dumps({
        "margin_rl": margin_rl.__file__,
        "envs": margin_rl.envs.__file__,
        "robots": robots,
        "toplevel_envs": importlib.util.find_spec("envs") is not None,
        "toplevel_train": importlib.util.find_spec("train") is not None,
        "toplevel_assets": importlib.util.find_spec("assets") is not None,
    }))
    """
)


def _source_files() -> set[str]:
    """Wheel paths that the source tree must produce (modules, MJCF assets, bundled weights and policies)."""
    mapping = {
        "margin_rl": "margin_rl",
        "envs": "margin_rl/envs",
        "train": "margin_rl/train",
        "assets": "margin_rl/assets",
    }
    expected = set()
    for src, dest in mapping.items():
        for path in (ROOT / src).rglob("*"):
            if "__pycache__" in path.parts or not path.is_file():
                continue
            bundled = "weights" in path.parts or "bundled" in path.parts
            if path.suffix in {".py", ".xml"} or path.name == "py.typed" or bundled:
                expected.add(f"{dest}/{path.relative_to(ROOT / src).as_posix()}")
    return expected


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(out), str(ROOT)],
        check=True,
        env={**os.environ, "PIP_NO_INPUT": "1"},
    )
    (path,) = out.glob("margin_rl-*.whl")
    return path


def test_wheel_contains_every_module_and_asset(wheel: Path) -> None:
    names = set(zipfile.ZipFile(wheel).namelist())
    missing = _source_files() - names
    assert not missing, f"files missing from the wheel: {sorted(missing)}"
    assert not any(n.startswith(("envs/", "train/", "assets/", "tests/")) for n in names)


def test_installed_wheel_loads_both_robots(wheel: Path, tmp_path: Path) -> None:
    env_dir = tmp_path / "venv"
    venv.EnvBuilder(with_pip=False).create(env_dir)
    python = env_dir / "bin" / "python"
    # The fresh environment sees the already installed dependencies through a .pth path entry.
    # A plain path line does not run the .pth files found there, so the editable install of
    # margin_rl in the development environment stays invisible.
    site = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    deps = sorted({sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]})
    Path(site, "_margin_rl_test_deps.pth").write_text("\n".join(deps) + "\n")
    # Replay the dependencies' own .pth hooks (Pinocchio's cmeel prefix needs one), after the path
    # line above (.pth files run in name order), but never the editable-install hook of margin_rl.
    for dep in deps:
        for pth in sorted(Path(dep).glob("*.pth")):
            if "margin_rl" not in pth.name:
                Path(site, f"zz_{pth.name}").write_text(pth.read_text())
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "-q", str(wheel)],
        check=True,
        env={**os.environ, "PIP_NO_INPUT": "1"},
    )
    result = subprocess.run(
        [str(python), "-c", PROBE],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"},
    )
    assert result.returncode == 0, result.stderr
    info = json.loads(result.stdout.strip().splitlines()[-1])
    assert info["margin_rl"].startswith(str(env_dir)), info["margin_rl"]
    assert info["envs"].startswith(str(env_dir)), info["envs"]
    for name, mass in (("anymal_b", 30.4214), ("anymal_c", 52.13485)):
        robot = info["robots"][name]
        assert robot["xml"].startswith(str(env_dir)) and robot["scene"].startswith(str(env_dir))
        assert abs(robot["mass"] - mass) < 1e-3
    assert not (info["toplevel_envs"] or info["toplevel_train"] or info["toplevel_assets"])
