"""The package's layers import in one direction only: robot -> stability -> envs -> train, planning on top.

Inside the stability layer: geometry (robot-agnostic) -> analytic -> fwp, learned.

Every ``import`` and ``from ... import`` of every module (at the top or inside a function) is read with
``ast`` and checked against :data:`ALLOWED`; the environments never import SB3 or rsl-rl, and the stability
core (the robot-agnostic criteria) never imports the robot layer.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCE_FOLDERS = {"margin_rl": "margin_rl", "envs": "margin_rl.envs", "train": "margin_rl.train"}
"""Repository folder -> the package it is installed as (pyproject's package-dir)."""

BASE_MODULES = (
    "margin_rl.arrays",
    "margin_rl.atomic",
    "margin_rl.network",
    "margin_rl.plotting",
    "margin_rl.provenance",
    "margin_rl.registration",
)


def layer_of(module: str) -> str:
    """The layer of a first-party module name."""
    if module in BASE_MODULES:
        return "base"
    parts = module.split(".")
    if len(parts) == 1 or parts[1] in ("robot", "__main__"):
        return "robot"  # the package's face loads the robot layer only
    if parts[1] == "stability" and len(parts) > 2:
        if parts[2] not in STABILITY_PACKAGES:
            raise AssertionError(f"{module}: stability modules live in one of the sub-packages {STABILITY_PACKAGES}")
        return f"stability.{parts[2]}"
    if parts[1] in ("stability", "slip", "planning", "envs", "train"):
        return parts[1]
    raise AssertionError(f"{module}: no layer declared; add it to tests/test_layers.py")


STABILITY_PACKAGES = ("geometry", "analytic", "fwp", "learned")
"""The sub-packages of margin_rl.stability, lowest first."""
STABILITY = {"stability", *(f"stability.{p}" for p in STABILITY_PACKAGES)}

ALLOWED: dict[str, set[str]] = {
    "base": {"base"},
    "robot": {"base", "robot"},
    "stability.geometry": {"base", "stability.geometry"},  # robot-agnostic: never the robot layer
    "stability.analytic": {"base", "robot", "stability.geometry", "stability.analytic"},
    "stability.fwp": {"base", "robot", "stability.geometry", "stability.analytic", "stability.fwp"},
    "stability.learned": {"base", "robot", "stability.geometry", "stability.analytic", "stability.learned"},
    "stability": {"base", "robot", *STABILITY},  # the layer's face re-exports its sub-packages
    "slip": {"base", "slip"},
    "planning": {"base", "robot", *STABILITY, "envs", "planning"},  # envs: the rough terrain's height field
    "envs": {"base", "robot", *STABILITY, "slip", "envs"},
    "train": {"base", "robot", *STABILITY, "slip", "envs", "train"},
}
"""Layer -> the layers its modules may import."""

FORBIDDEN_THIRD_PARTY = {
    "envs": ("stable_baselines3", "rsl_rl"),
    **{layer: ("gymnasium",) for layer in STABILITY},
    "stability.geometry": ("gymnasium", "torch"),
    "robot": ("torch",),
}
ROBOT_AGNOSTIC = tuple(f"margin_rl.stability.fwp.{name}" for name in ("polytope", "programs", "factor"))
"""Modules outside stability.geometry that hold robot-agnostic criteria (seed 004's polytope, programs, factor)."""


def source_modules() -> dict[str, Path]:
    modules = {}
    for folder, package in SOURCE_FOLDERS.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            relative = path.relative_to(ROOT / folder).with_suffix("")
            parts = [p for p in relative.parts if p != "__init__"]
            modules[".".join([package, *parts])] = path
    return modules


def imported_names(path: Path, module: str) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in ``path``, at the top or inside a function."""
    is_package = path.name == "__init__.py"
    names = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")
                base = base if is_package else base[:-1]
                base = base[: len(base) - node.level + 1]
                target = ".".join([*base, node.module] if node.module else base)
            else:
                target = node.module or ""
            names.append((node.lineno, target))
            # `from margin_rl import envs` or `from margin_rl.stability import region` imports a module
            names += [(node.lineno, f"{target}.{alias.name}") for alias in node.names]
    return names


MODULES = source_modules()


def test_every_module_has_a_layer() -> None:
    assert len(MODULES) > 50
    for module in MODULES:
        layer_of(module)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_follow_the_layers(module: str) -> None:
    layer = layer_of(module)
    wrong = []
    for line, target in imported_names(MODULES[module], module):
        top = target.split(".")[0]
        if top == "margin_rl":
            if target not in MODULES:
                continue  # a name imported from a module, e.g. `from margin_rl import load_robot`
            if layer_of(target) not in ALLOWED[layer]:
                wrong.append(f"line {line}: {target} ({layer_of(target)} layer)")
        elif top in FORBIDDEN_THIRD_PARTY.get(layer, ()):
            wrong.append(f"line {line}: {target} (third party, never in the {layer} layer)")
        if module in ROBOT_AGNOSTIC and target.startswith("margin_rl.robot"):
            wrong.append(f"line {line}: {target} (the stability core is robot-agnostic)")
    assert not wrong, f"{module} ({layer} layer) imports against the layer order:\n" + "\n".join(wrong)


def test_the_checker_catches_an_upward_import(tmp_path: Path) -> None:
    """The walk sees imports inside functions and relative imports (a check that cannot pass vacuously)."""
    path = tmp_path / "mod.py"
    path.write_text("def f():\n    from ...envs import core\n    import margin_rl.train.commands.train\n")
    targets = [t for _, t in imported_names(path, "margin_rl.stability.geometry.mod")]
    assert targets == ["margin_rl.envs", "margin_rl.envs.core", "margin_rl.train.commands.train"]
    assert {layer_of(t) for t in targets} - ALLOWED["stability.geometry"] == {"envs", "train"}
    # within the stability layer too: the robot-agnostic geometry may not import the analytic sub-package
    assert layer_of("margin_rl.stability.analytic.margin") not in ALLOWED["stability.geometry"]


def test_the_package_root_does_not_import_the_environments() -> None:
    """``import margin_rl`` registers the ids by name; the env modules load when an env is made."""
    import subprocess
    import sys

    code = (
        "import sys, gymnasium as gym, margin_rl\n"
        "assert 'margin_rl.envs' not in sys.modules, 'import margin_rl imported margin_rl.envs'\n"
        "assert 'margin_rl/AnymalB-v1' in gym.registry and 'margin_rl/SLIPHopper-v0' in gym.registry\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


def test_a_fresh_interpreter_makes_an_env_through_the_module_syntax() -> None:
    """Without ``import margin_rl``: Gymnasium's ``module:id`` syntax imports the package, which registers."""
    import subprocess
    import sys

    code = (
        "import gymnasium as gym\n"
        "env = gym.make('margin_rl:margin_rl/AnymalB-v1', margin='none')\n"
        "obs, _ = env.reset(seed=0)\n"
        "assert obs.shape == (48,)\n"
        "vec = gym.make_vec('margin_rl/AnymalC-v1', num_envs=2, margin='none')\n"
        "assert vec.reset(seed=0)[0].shape == (2, 48)\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


def first_party_imports(module: str) -> set[str]:
    """First-party modules that ``module`` imports, at load time or inside a function."""
    targets = set()
    for _, target in imported_names(MODULES[module], module):
        while target and target not in MODULES:  # `from package import name` names a module or a name
            target = target.rpartition(".")[0]
        if target and target != module:
            targets.add(target)
    return targets


def test_no_module_imports_itself_in_a_circle() -> None:
    graph = {module: first_party_imports(module) for module in MODULES}
    cycles = []
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            # a package's face importing its own submodules (and they importing the face's parents) is normal
            if node.startswith(nxt + ".") or nxt.startswith(node + "."):
                continue
            if state.get(nxt) == 1:
                cycles.append(" -> ".join([*path[path.index(nxt) :], nxt]))
            elif nxt not in state:
                visit(nxt, [*path, nxt])
        state[node] = 2

    for module in sorted(graph):
        if module not in state:
            visit(module, [module])
    assert not cycles, "modules that import each other (at load time or lazily):\n" + "\n".join(cycles)


def test_the_gpu_training_path_loads_no_pinocchio_casadi_or_clarabel() -> None:
    """The environments with the learned margin, the rsl-rl backend and the train command run on a machine that has
    only mujoco, mujoco-warp, warp-lang, gymnasium, rsl-rl-lib and tensordict beside torch: Pinocchio, CasADi and
    Clarabel load where the analytic margin, the planners or the crawl need them, not before."""
    import subprocess
    import sys

    code = (
        "import sys, numpy as np, gymnasium as gym, margin_rl\n"
        "import margin_rl.train.commands.train\n"
        "from margin_rl.train import make_rsl_env\n"
        "env = make_rsl_env('margin_rl/AnymalC-v1', 2, seed=0)\n"
        "vec = gym.make_vec('margin_rl/AnymalB-v1', num_envs=2)\n"
        "vec.reset(seed=0); vec.step(np.zeros((2, 12)))\n"
        "loaded = [m for m in ('pinocchio', 'casadi', 'clarabel') if m in sys.modules]\n"
        "assert not loaded, f'the GPU training path imported {loaded}'\n"
        "from margin_rl.stability import analytic_margin\n"
        "assert 'clarabel' in sys.modules  # loaded on first use of a name that needs it\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=300)
