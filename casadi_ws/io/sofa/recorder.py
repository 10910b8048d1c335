"""A recording stand-in for SOFA's Python API: run a scene's ``createScene`` with no SOFA installed.

``record(path)`` executes the scene file (``.py`` / ``.pyscn``) with modules ``Sofa``, ``Sofa.Core``,
``Sofa.Simulation``, ``Sofa.Helper``, ``Sofa.constants``, ``SofaRuntime``, the numerics of ``splib3`` and
the stlib3/softrobots prefabs replaced by stand-ins (:mod:`.api`, :mod:`.prefabs`), calls its ``createScene(root)``, and returns the recorded graph: nodes
with their children and objects, each object its SOFA type and its data as given. Nothing is simulated; a
data a scene reads back (``node.roi.indices``) is a :class:`Data` whose ``getLinkPath()`` gives the
``@path.name`` link SOFA would resolve. ``.scn`` XML scenes are parsed into the same graph.

Executing a scene runs the user's own Python code, on purpose, as SOFA's ``runSofa`` would.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from .api import Data, Node, Object, SceneError, stand_in_modules, stub_missing, stubbed_module
from .prefabs import VENDOR
from .prefabs import stand_in_modules as prefab_modules

__all__ = ["Data", "Node", "Object", "SceneError", "record"]


class _StubFinder:
    """Last on ``sys.meta_path`` while a scene runs: a module nothing else finds (another plugin's helpers,
    ``splib3.objectmodel``, ``rclpy``) is a module of stubs (:class:`Stub`) rather than an ImportError."""

    def __init__(self, used: set):
        self.used, self.made = used, []

    def find_spec(self, name, path=None, target=None):
        return importlib.util.spec_from_loader(name, self)

    def create_module(self, spec):
        self.made.append(spec.name)
        self.used.add(spec.name)
        return stubbed_module(spec.name, self.used)

    def exec_module(self, module):
        pass


@contextlib.contextmanager
def _installed(modules: dict, scene_dir: Path, used: set):
    saved = {k: sys.modules.get(k) for k in modules}
    sys.modules.update(modules)
    sys.path.insert(0, str(scene_dir))
    finder = _StubFinder(used)
    sys.meta_path.append(finder)
    before = set(sys.modules)
    try:
        yield
    finally:
        sys.meta_path.remove(finder)
        for k in finder.made:
            sys.modules.pop(k, None)
        sys.path.remove(str(scene_dir))
        for k, v in saved.items():
            if v is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = v
        # the scene's own helper modules (FingerController) and the vendored parts run against this
        # recording's stand-ins: they must not leak into the next recording
        for k in set(sys.modules) - before:
            file = getattr(sys.modules.get(k), "__file__", None)
            if file and (Path(file).resolve().parent == scene_dir.resolve() or VENDOR in Path(file).resolve().parents):
                sys.modules.pop(k, None)


def record(path: str | Path) -> Node:
    """The graph a scene file builds: ``.py``/``.pyscn`` by running ``createScene``, ``.scn`` by parsing."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: scene file not found")
    if path.suffix.lower() == ".scn":
        return _parse_xml(path)
    modules = stand_in_modules()
    modules.update(prefab_modules(modules))
    used: set[str] = set()
    for m in modules.values():
        stub_missing(m, used)
    spec = importlib.util.spec_from_loader(f"_casadi_ws_scene_{abs(hash(str(path)))}", loader=None)
    module = importlib.util.module_from_spec(spec)
    module.__file__ = str(path.resolve())
    root = Node("root")
    out = io.StringIO()
    with _installed(modules, path.resolve().parent, used), contextlib.redirect_stdout(out):
        try:
            code = compile(path.read_text(), str(path), "exec")
            exec(code, module.__dict__)  # noqa: S102 - the user's scene, run on purpose
            if "createScene" not in module.__dict__:
                raise SceneError(f"{path}: defines no createScene(rootNode)")
            module.createScene(root)
        except SceneError:
            raise
        except ModuleNotFoundError as exc:
            raise SceneError(f"{path}: imports '{exc.name}', which the SOFA stand-in does not provide (it "
                             f"offers Sofa, SofaRuntime, splib3's numerics and the stlib3/softrobots prefabs of "
                             f"docs/sofa.md)") from None
        except Exception as exc:  # the user's code: report where it failed, in one line
            tb = exc.__traceback__
            line = None
            while tb is not None:
                if tb.tb_frame.f_code.co_filename == str(path):
                    line = tb.tb_lineno
                tb = tb.tb_next
            where = f" (line {line})" if line else ""
            raise SceneError(f"{path}: createScene failed{where}: {type(exc).__name__}: {exc}") from None
    root.__dict__["stubbed"] = sorted(used)
    return root


def _xml_value(text: str):
    """A data value of a .scn attribute: numbers where it is numbers, else the string."""
    parts = text.replace(",", " ").split()
    try:
        nums = [float(p) for p in parts]
    except ValueError:
        return text
    return nums[0] if len(nums) == 1 else nums


def _parse_xml(path: Path) -> Node:
    try:
        tree = ET.parse(path)
    except ET.ParseError as exc:
        raise SceneError(f"{path}: malformed XML: {exc}") from None

    def build(elem, node):
        for child in elem:
            if child.tag == "Node":
                sub = node.addChild(child.get("name", "node"))
                for k, v in child.attrib.items():
                    if k != "name":
                        sub.data[k] = _xml_value(v)
                build(child, sub)
            else:
                text = ("name", "filename", "src", "template", "method", "valueType")
                node.addObject(child.tag, **{k: (v if k in text else _xml_value(v)) for k, v in child.attrib.items()})

    top = tree.getroot()
    root = Node(top.get("name", "root"))
    for k, v in top.attrib.items():
        if k != "name":
            root.data[k] = _xml_value(v)
    build(top, root)
    return root
