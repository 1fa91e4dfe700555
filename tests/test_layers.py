"""The layers hold: import-linter's contract (pyproject.toml) is kept, it is the layer diagram of
docs/architecture.md ("The layers"), and no dpc_mjx modules import each other in a circle
(imports inside functions counted)."""

import pathlib
import re
import subprocess
import sys
import tomllib

import grimp
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = "dpc_mjx"


def _contract_layers(container: str = PACKAGE) -> list[str]:
    """The layers of the layers contract of `container` (the library's, or a package's inside
    it), top to bottom, as written ('deploy | sac', ...)."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    layered = [c for c in config["contracts"] if c["type"] == "layers"]
    (contract,) = [c for c in layered if c["containers"] == [container]]
    assert contract["exhaustive"]
    return contract["layers"]


def _names(layer: str) -> tuple[frozenset[str], bool]:
    """({module names}, independent): 'a | b' independent siblings, 'a : b' siblings that may
    import each other (import-linter's syntax)."""
    sep = ":" if ":" in layer else "|"
    return frozenset(n.strip() for n in layer.split(sep)), sep == "|"


def _drawn_layers() -> list[tuple[frozenset[str], bool]]:
    """The rows of the diagram in docs/architecture.md ("The layers"), top to bottom: a row starts
    with one space and its label (`run/`, `deploy.py | sac/`, `utilities`), the rest of the row
    is indented further. The utilities row stands for the top-level modules it names."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    start = text.index("## The layers")
    section = text[start : text.index("\n## ", start + 1)]
    diagram = section.split("```")[1]
    rows: list[tuple[str, list[str]]] = []
    for line in diagram.splitlines():
        label = re.match(r"^ ([a-z_]+(?:/|\.py)?(?: \| [a-z_]+(?:/|\.py)?)*)(?:\s|$)", line)
        if label:
            rows.append((label.group(1), [line]))
        elif rows:
            rows[-1][1].append(line)
    layers = []
    for label, lines in rows:
        if label == "utilities":
            named = re.findall(r"(?<![/\w])([a-z_0-9]+)\.py", " ".join(lines))
            layers.append((frozenset(named), False))
        else:
            parts = [re.sub(r"(/|\.py)$", "", p) for p in label.split(" | ")]
            layers.append((frozenset(parts), len(parts) > 1))
    return layers


def test_import_linter_keeps_the_contract():
    lint_imports = pathlib.Path(sys.executable).with_name("lint-imports")
    if not lint_imports.exists():
        pytest.fail("lint-imports is missing: pip install -e .[test] (make install does)")
    done = subprocess.run(
        [str(lint_imports), "--no-logo", "--no-cache"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, f"lint-imports: the layers are broken\n{done.stdout}{done.stderr}"


def test_the_contract_refuses_an_upward_import():
    """The contract as grimp reads it: kept by the code, broken once a layer imports one above."""
    layers = [
        grimp.Layer(*names, independent=ind) for names, ind in map(_names, _contract_layers())
    ]
    graph = grimp.build_graph(PACKAGE, cache_dir=None)
    check = {"layers": layers, "containers": {PACKAGE}}
    assert not graph.find_illegal_dependencies_for_layers(**check)
    graph.add_import(importer="dpc_mjx.robots.bases.a1", imported="dpc_mjx.policy.policy")
    (broken,) = graph.find_illegal_dependencies_for_layers(**check)
    assert (broken.importer, broken.imported) == ("dpc_mjx.robots", "dpc_mjx.policy")


def test_the_robots_contract_keeps_arms_and_bases_apart():
    """Inside `robots`: the assembly above the arms and the bases, which import neither each other
    nor the assembly, above the file reading they share; broken by an arm that imports a base."""
    robots = f"{PACKAGE}.robots"
    layers = [
        grimp.Layer(*names, independent=ind) for names, ind in map(_names, _contract_layers(robots))
    ]
    assert layers[1].independent and set(layers[1].module_tails) == {"arms", "bases"}
    graph = grimp.build_graph(PACKAGE, cache_dir=None)
    check = {"layers": layers, "containers": {robots}}
    assert not graph.find_illegal_dependencies_for_layers(**check)
    graph.add_import(importer=f"{robots}.arms.mount", imported=f"{robots}.bases.a1")
    (broken,) = graph.find_illegal_dependencies_for_layers(**check)
    assert (broken.importer, broken.imported) == (f"{robots}.arms", f"{robots}.bases")


def test_the_architecture_page_draws_the_layers_of_the_contract():
    drawn = _drawn_layers()
    declared = [_names(layer) for layer in _contract_layers()]
    assert [names for names, _ in drawn] == [names for names, _ in declared], (
        "docs/architecture.md's layer diagram and pyproject.toml's import-linter layers differ: "
        f"drawn {[sorted(n) for n, _ in drawn]}, contract {[sorted(n) for n, _ in declared]}"
    )
    for (names, apart), (_, independent) in zip(drawn, declared, strict=True):
        if apart:  # drawn 'a | b': siblings that do not import each other
            assert independent, f"{sorted(names)}: the page draws '|', the contract has ':'"


def _runtime_edges(graph) -> dict[str, set[str]]:
    """module -> the modules importing it runs: what it imports (inside functions too) and their
    packages' `__init__` (Python runs a package before its modules), less its own packages."""
    edges = {}
    for module in graph.modules:
        edges[module] = set()
        for imported in graph.find_modules_directly_imported_by(module):
            parts = imported.split(".")
            for target in (".".join(parts[:i]) for i in range(1, len(parts) + 1)):
                if target != module and not module.startswith(target + "."):
                    edges[module].add(target)
    return edges


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan's, iterative)."""
    index, low, on_stack, stack, found = {}, {}, set(), [], []
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
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
                    work.append((child, iter(sorted(edges[child]))))
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
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_no_import_cycle_among_the_modules():
    graph = grimp.build_graph(PACKAGE, cache_dir=None)
    cycles = _cycles(_runtime_edges(graph))
    assert not cycles, f"modules that import each other in a circle: {cycles}"
    # the check finds one: robots.bases.file -> run.cli -> ... -> robots.bases.file
    graph.add_import(importer="dpc_mjx.robots.bases.file", imported="dpc_mjx.run.cli")
    assert _cycles(_runtime_edges(graph))


def test_no_module_imports_its_own_package():
    """Names come from the module that defines them, never through a package's `__init__` (or
    the root's) that the importing module is part of: that is a circle at import time."""
    graph = grimp.build_graph(PACKAGE, cache_dir=None)
    upward = sorted(
        (module, imported)
        for module in graph.modules
        for imported in graph.find_modules_directly_imported_by(module)
        if module.startswith(imported + ".")
    )
    assert not upward, f"modules importing a package they belong to: {upward}"
