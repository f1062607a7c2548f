"""The layout rules of docs/architecture.md, checked on the source tree: the include graph of core/
has no cycle, folders only include downwards, and nothing outside a shape kind's own files asks
which kind a shape is."""
from __future__ import annotations

import os
import re

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CORE = os.path.join(ROOT, "core")
INCLUDE = re.compile(r'^\s*#\s*include\s+"(core/[^"]+)"', re.M)

# Which top-level folders of core/ each folder may include (besides itself). Arrows run one way:
# math <- geometry <- render <- diff -> guiding; io reads files into render's scene.
ALLOWED = {
    "math": set(),
    "geometry": {"math"},
    "render": {"math", "geometry"},
    "guiding": {"math"},
    "diff": {"math", "geometry", "render", "guiding"},
    "io": {"math", "geometry", "render"},
    "optim": {"math"},
}


def sources() -> list[str]:
    out = []
    for folder, _, files in os.walk(CORE):
        out += [os.path.relpath(os.path.join(folder, f), ROOT) for f in files if f.endswith((".h", ".cpp"))]
    return sorted(out)


def includes(path: str) -> list[str]:
    with open(os.path.join(ROOT, path)) as f:
        return INCLUDE.findall(f.read())


def find_cycle(graph: dict[str, list[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in graph.get(node, []):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        stack.pop()
        state[node] = 2
        return None

    for node in graph:
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def top_folder(path: str) -> str:
    return path.split("/")[1]


def test_the_include_graph_of_core_has_no_cycle():
    files = sources()
    graph = {f: includes(f) for f in files}
    for f, incs in graph.items():
        for inc in incs:
            assert os.path.exists(os.path.join(ROOT, inc)), f"{f} includes {inc}, which does not exist"
    assert find_cycle(graph) is None, f"include cycle: {' -> '.join(find_cycle(graph))}"
    # Folders (the sub-folders of core/geometry and core/diff count as their own nodes).
    def folder(path: str) -> str:
        return os.path.dirname(path)
    folders: dict[str, set[str]] = {}
    for f, incs in graph.items():
        folders.setdefault(folder(f), set()).update(folder(i) for i in incs if folder(i) != folder(f))
    cycle = find_cycle({k: sorted(v) for k, v in folders.items()})
    assert cycle is None, f"folder include cycle: {' -> '.join(cycle)}"


def test_folders_include_only_the_layers_below_them():
    wrong = []
    for f in sources():
        for inc in includes(f):
            a, b = top_folder(f), top_folder(inc)
            if a != b and b not in ALLOWED[a]:
                wrong.append(f"{f} includes {inc} ({a} -> {b})")
    assert not wrong, "\n".join(wrong)


def test_nothing_outside_a_shape_kind_asks_which_kind_a_shape_is():
    """Dispatch is std::visit over the shape variant (core/geometry/shapes/shape.h); kind tests such as
    is_mesh() turn a new kind into a silent zero. The shapes' own files may name their kind."""
    own = re.compile(r"^core/(geometry|diff)/shapes/|^core/diff/estimators/heightfield")
    test = re.compile(r"\bis_(mesh|sphere|heightfield|curve|sdf)\s*\(|holds_alternative<(Mesh|Sphere|Heightfield)>")
    offenders = []
    for root in ("core", "bindings"):
        for folder, _, files in os.walk(os.path.join(ROOT, root)):
            for name in files:
                if not name.endswith((".h", ".cpp")):
                    continue
                rel = os.path.relpath(os.path.join(folder, name), ROOT)
                if own.search(rel):
                    continue
                with open(os.path.join(ROOT, rel)) as fh:
                    for n, line in enumerate(fh, 1):
                        if test.search(line):
                            offenders.append(f"{rel}:{n}: {line.strip()}")
    assert not offenders, "\n".join(offenders)
