"""Layers only point down, and no modules import each other in a circle (read from the source with ast).

Layers, bottom to top: the environment core (``crowdnav/`` except its CLI), the agents
(``agents/``, installed as ``crowdnav.agents``), evaluation (``evaluation/``, as
``crowdnav.evaluation``), the command line (``crowdnav/cli``). A module may import its own
layer and those below it, also inside functions; circles are looked for among all imports,
those inside functions included (a lazy import is still a dependency).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests.paths import REPO

ROOT = REPO
FOLDERS = {"crowdnav": "crowdnav", "agents": "crowdnav.agents", "evaluation": "crowdnav.evaluation"}
"""Source folder -> the package it installs as (pyproject.toml's package-dir)."""
LAYERS = ("core", "agents", "evaluation", "cli")


def source_modules() -> dict[str, Path]:
    """Installed module name -> source file, for every Python file of the layered packages."""
    modules = {}
    for folder, package in FOLDERS.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            parts = path.relative_to(ROOT / folder).with_suffix("").parts
            name = ".".join((package, *parts)).removesuffix(".__init__")
            modules[name] = path
    return modules


MODULES = source_modules()


def layer(module: str) -> str:
    for name, prefix in (("cli", "crowdnav.cli"), ("cli", "crowdnav.__main__"), ("agents", "crowdnav.agents"),
                         ("evaluation", "crowdnav.evaluation")):
        if module == prefix or module.startswith(prefix + "."):
            return name
    return "core"


def resolve(name: str) -> str | None:
    """The module of ours that ``name`` (a module or a name in one) belongs to, or None for other packages."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def imports(module: str, *, in_functions: bool) -> set[str]:
    """Our modules that ``module`` imports (``in_functions``: also those imported inside functions)."""
    path = MODULES[module]
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)) and not in_functions:
                continue
            names: list[str] = []
            if isinstance(child, ast.Import):
                names = [alias.name for alias in child.names]
            elif isinstance(child, ast.ImportFrom):
                base = child.module or ""
                if child.level:
                    parts = package.split(".")[: len(package.split(".")) - child.level + 1]
                    base = ".".join([*parts, base] if base else parts)
                names = [base, *(f"{base}.{alias.name}" for alias in child.names)]
            for name in names:
                target = resolve(name)
                # a module's own ancestors are imported before it anyway: not an edge
                if target and target != module and not module.startswith(target + "."):
                    found.add(target)
            visit(child)

    visit(ast.parse(path.read_text(encoding="utf-8")))
    return found


def test_every_source_file_maps_to_its_layer():
    assert layer("crowdnav.worlds.compiled") == layer("crowdnav.rendering.episodes") == "core"
    assert layer("crowdnav.agents.runs.folder") == "agents" and layer("crowdnav.evaluation.jobs") == "evaluation"
    assert layer("crowdnav.cli.train") == layer("crowdnav.__main__") == "cli"
    assert {layer(module) for module in MODULES} == set(LAYERS)
    assert len(MODULES) > 60


@pytest.mark.parametrize("lower", LAYERS[:-1])
def test_no_module_imports_a_higher_layer_even_inside_functions(lower):
    upward = sorted(f"{module} -> {target}" for module in MODULES if layer(module) == lower
                    for target in imports(module, in_functions=True) if LAYERS.index(layer(target)) > LAYERS.index(lower))
    assert upward == []


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components of ``graph`` (iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                components.append(sorted(component))
    return components


def test_the_circle_finder_finds_a_circle():
    assert sorted(map(len, strongly_connected({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}))) == [1, 3]


def test_no_modules_import_each_other_in_a_circle_even_through_imports_inside_functions():
    graph = {module: imports(module, in_functions=True) for module in MODULES}
    assert [component for component in strongly_connected(graph) if len(component) > 1] == []


def test_inside_the_envs_the_engines_never_import_the_vector_env_above_them():
    """crowdnav/envs/engines/ (the engine protocol and its backends) sits below crowdnav/envs/vector/, which reads it through
    the protocol: the engines import nothing of the vector env, even inside functions."""
    engines = [module for module in MODULES if module.startswith("crowdnav.envs.engines")]
    assert len(engines) >= 9
    upward = sorted(f"{module} -> {target}" for module in engines for target in imports(module, in_functions=True)
                    if target == "crowdnav.envs.vector" or target.startswith("crowdnav.envs.vector."))
    assert upward == []
