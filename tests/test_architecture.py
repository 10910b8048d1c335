"""The package's layers: imports point one way (the folder tree is the architecture), the API is explicit."""

import ast
import importlib
from pathlib import Path

import casadi_ws

PKG = Path(casadi_ws.__file__).parent
# lower layers first; a module may import only from its own layer and those before it
LAYERS = ["status", "actuation", "fem", "solvers", "nlp", "runtime", "workspace", "control", "io", "study", "cli"]


def _imports(path: Path) -> set[str]:
    """Sub-packages of casadi_ws that the module at ``path`` imports (at any depth of the code)."""
    rel = path.relative_to(PKG).with_suffix("")
    parts = list(rel.parts)
    here = parts[:-1] if parts[-1] != "__init__" else parts[:-1]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[: len(here) - (node.level - 1)] if node.level > 1 else here
                target = base + (node.module.split(".") if node.module else [])
            elif node.module and node.module.startswith("casadi_ws"):
                target = node.module.split(".")[1:]
            else:
                continue
            if target:
                out.add(target[0])
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("casadi_ws."):
                    out.add(a.name.split(".")[1])
    return out


def _layer(path: Path) -> str:
    return path.relative_to(PKG).with_suffix("").parts[0]


def test_imports_point_down_the_layers():
    wrong = []
    for path in PKG.rglob("*.py"):
        layer = _layer(path)
        if layer == "__init__":
            continue  # the top level gathers the public API from every layer
        assert layer in LAYERS, f"{path}: a new layer? add it to LAYERS in its place"
        for target in _imports(path) - {layer}:
            if target not in LAYERS or LAYERS.index(target) > LAYERS.index(layer):
                wrong.append(f"{path.relative_to(PKG)} ({layer}) imports {target}")
    assert not wrong, "imports against the layers:\n" + "\n".join(sorted(wrong))


def test_no_import_cycle_between_modules():
    """Module-level graph (imports inside functions included): no cycle, so no layer hides one either."""
    graph = {}
    for path in PKG.rglob("*.py"):
        rel = path.relative_to(PKG).with_suffix("")
        name = ".".join(p for p in rel.parts if p != "__init__") or "__init__"
        tree = ast.parse(path.read_text())
        deps = set()
        here = list(rel.parts[:-1])
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level:
                base = here[: len(here) - (node.level - 1)] if node.level > 1 else here
                mod = base + (node.module.split(".") if node.module else [])
                for a in node.names:
                    cand = ".".join(mod + [a.name])
                    deps.add(cand if (PKG / Path(*mod, a.name + ".py")).exists() else ".".join(mod))
        graph[name] = {d for d in deps if d and d != name}
    state: dict[str, int] = {}

    def visit(n, stack):
        state[n] = 1
        for d in graph.get(n, ()):
            if state.get(d) == 1:
                raise AssertionError("import cycle: " + " -> ".join(stack + [n, d]))
            if d in graph and not state.get(d):
                visit(d, stack + [n])
        state[n] = 2

    for n in graph:
        if n != "__init__" and not state.get(n):
            visit(n, [])


def test_public_api_is_listed_and_importable():
    for name in casadi_ws.__all__:
        assert hasattr(casadi_ws, name), name
    for layer in LAYERS[1:-1]:
        mod = importlib.import_module(f"casadi_ws.{layer}")
        assert mod.__all__, layer
        for name in mod.__all__:
            assert hasattr(mod, name), f"casadi_ws.{layer}.{name}"
    for name in ("forward", "forward_backward", "compare", "load_result", "WorkspaceResult", "reach", "Status"):
        assert name in casadi_ws.__all__


def test_no_module_below_io_reads_what_only_io_s_problem_has():
    """The layers below ``io`` read a model's specification (:class:`casadi_ws.fem.spec.ModelSpec`), never
    what io's Problem adds (the command line's ``workspace`` defaults, the study's ``task``...): every attribute
    they read of a ``problem``/``spec`` (a variable, ``self.``, ``model.``) is a ModelSpec field, property or
    method, and a model's specification is ``model.spec``."""
    import dataclasses

    from casadi_ws.fem.spec import ModelSpec

    allowed = {f.name for f in dataclasses.fields(ModelSpec)} | {
        n for n in dir(ModelSpec) if not n.startswith("_")}
    below = LAYERS[: LAYERS.index("io")]
    wrong = []
    for path in PKG.rglob("*.py"):
        if _layer(path) not in below:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.Attribute):
                continue
            v = node.value
            holder = v.id if isinstance(v, ast.Name) else v.attr if isinstance(v, ast.Attribute) else None
            base = v.value.id if isinstance(v, ast.Attribute) and isinstance(v.value, ast.Name) else None
            if node.attr == "problem" and isinstance(v, ast.Name) and v.id in ("model", "m"):
                wrong.append(f"{path.relative_to(PKG)}:{node.lineno}: {v.id}.problem (the model's is .spec)")
            described = base == "result" or (base == "self" and path.name == "result.py")  # a result's dict
            if holder in ("problem", "pb", "spec") and not described and node.attr not in allowed:
                wrong.append(f"{path.relative_to(PKG)}:{node.lineno}: .{node.attr} of a {holder}")
    assert not wrong, "reads beyond a ModelSpec below io:\n" + "\n".join(sorted(wrong))
