"""The stand-in for SOFA's Python API that scenes are recorded against (:mod:`.recorder`): nodes, objects,
data and links as ``Sofa.Core`` has them, the controller base class, splib3's numerics, and the modules
that carry them."""

from __future__ import annotations

import math
import types

import numpy as np

__all__ = ["Controller", "Data", "Node", "Object", "SceneError", "Stub", "stand_in_modules", "stub_missing",
           "stubbed_module"]

NODE_DEFAULTS = {"gravity": [0.0, -9.81, 0.0], "dt": 0.01, "time": 0.0, "animate": False, "bbox": None,
                 "activated": True}
"""SOFA's built-in node data and their defaults: a scene may read one it never set (``root.dt.value``); only
those written are recorded (so an unset gravity stays unset for the units' rule)."""


class SceneError(ValueError):
    """A scene that cannot be recorded or translated; ``str()`` is one line naming the scene."""


class Data:
    """One data field of a recorded object or node: its value (written back to its owner when set), and
    the link path SOFA would give it."""

    def __init__(self, owner, name: str, value=None):
        self.__dict__.update(owner=owner, name=name)
        owner.__dict__["data"].setdefault(name, value)

    @property
    def value(self):
        return self.owner.__dict__["data"].get(self.name)

    @value.setter
    def value(self, v):
        self.owner.__dict__["data"][self.name] = v.value if isinstance(v, Data) else v

    def getLinkPath(self) -> str:  # noqa: N802 (SOFA's name)
        return f"@{self.owner.path()}.{self.name}"

    linkpath = property(getLinkPath)

    def getValueString(self) -> str:  # noqa: N802
        return str(self.value)

    def setParent(self, other):  # noqa: N802
        """A link to another data (SOFA's data engine graph): its value now, as the recording's."""
        if isinstance(other, Data):
            self.value = other.value
        elif isinstance(other, str):
            self.value = other

    def __getitem__(self, i):
        return self.value[i]

    def __len__(self):
        return len(self.value)

    def __repr__(self):
        return f"Data({self.getLinkPath()}={self.value!r})"


class _NodeData(Data):
    """A built-in data of a node (:data:`NODE_DEFAULTS`): reads SOFA's default until written."""

    def __init__(self, owner, name: str):
        self.__dict__.update(owner=owner, name=name)

    @property
    def value(self):
        return self.owner.__dict__["data"].get(self.name, NODE_DEFAULTS.get(self.name))

    @value.setter
    def value(self, v):
        self.owner.__dict__["data"][self.name] = v.value if isinstance(v, Data) else v


class Object:
    """A recorded component: its SOFA type, name and data (keyword arguments as given)."""

    def __init__(self, type_: str, parent: "Node | None" = None, **data):
        self.__dict__["type"] = type_
        self.__dict__["parent"] = parent
        self.__dict__["data"] = dict(data)
        self.__dict__["fields"] = {}

    @property
    def name(self) -> str:
        return str(self.data.get("name", self.type))

    def path(self) -> str:
        return f"{self.parent.path()}/{self.name}" if self.parent is not None else self.name

    def getData(self, name):  # noqa: N802
        return self.findData(name)

    def findData(self, name):  # noqa: N802
        if name not in self.fields:
            self.fields[name] = Data(self, name)
        return self.fields[name]

    def getLinkPath(self) -> str:  # noqa: N802
        return f"@{self.path()}"

    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        return self.findData(name)

    def __setattr__(self, name, value):
        self.data[name] = value.value if isinstance(value, Data) else value

    def init(self):
        pass

    def reinit(self):
        pass

    def __repr__(self):
        return f"<{self.type} {self.path()}>"


class Node:
    """A recorded node: children, objects, and node data (``gravity``, ``dt``)."""

    def __init__(self, name: str = "root", parent: "Node | None" = None):
        self.__dict__.update(name=name, parent=parent, children=[], objects=[], data={})

    def path(self) -> str:
        return "" if self.parent is None else f"{self.parent.path()}/{self.name}"

    def addChild(self, child, **data):  # noqa: N802
        if isinstance(child, Node):
            child.__dict__["parent"] = self
            node = child
        else:
            node = Node(str(child), self)
        node.data.update(data)
        self.children.append(node)
        return node

    def addObject(self, type_, **data):  # noqa: N802
        if isinstance(type_, Controller):
            type_.__dict__["parent"] = self
            self.objects.append(type_)
            return type_
        obj = Object(str(type_), self, **data)
        self.objects.append(obj)
        return obj

    def removeObject(self, obj):  # noqa: N802
        self.objects[:] = [o for o in self.objects if o is not obj]

    def removeChild(self, child):  # noqa: N802
        self.children[:] = [c for c in self.children if c is not child]

    def addData(self, name, value=None, *args, **kwargs):  # noqa: N802
        self.data[name] = kwargs.get("value", value)

    def getChild(self, name):  # noqa: N802
        return next((c for c in self.children if c.name == name), None)

    def getObject(self, name):  # noqa: N802
        return next((o for o in self.objects if o.name == name), None)

    def getRoot(self):  # noqa: N802
        return self if self.parent is None else self.parent.getRoot()

    def getContext(self):  # noqa: N802
        return self

    def findData(self, name):  # noqa: N802
        if name in NODE_DEFAULTS and name not in self.data:
            return _NodeData(self, name)
        return Data(self, name)

    getData = findData

    def getMechanicalState(self):  # noqa: N802
        return next((o for o in self.objects if o.type == "MechanicalObject"), None)

    def getChildren(self):  # noqa: N802
        return list(self.children)

    def getObjects(self):  # noqa: N802
        return list(self.objects)

    def hasObject(self, name) -> bool:  # noqa: N802
        return self.getObject(name) is not None

    def getPathName(self) -> str:  # noqa: N802
        return self.path() or "/"

    def getLinkPath(self) -> str:  # noqa: N802
        return f"@{self.path()}"

    def init(self):
        pass

    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        for c in self.children:
            if c.name == name:
                return c
        for o in self.objects:
            if o.name == name:
                return o
        if name in self.data:
            return Data(self, name)
        if name in NODE_DEFAULTS:
            return _NodeData(self, name)
        raise AttributeError(f"node '{self.path() or '/'}' has no child, object or data named '{name}'")

    def __setattr__(self, name, value):
        if isinstance(value, (Node, Object, Controller)) or callable(value):
            self.__dict__[name] = value  # a prefab keeping its parts (self.loader = self.addObject(...))
        else:
            self.data[name] = value.value if isinstance(value, Data) else value

    def walk(self):
        """This node and all below it, depth first."""
        yield self
        for c in self.children:
            yield from c.walk()

    def __repr__(self):
        return f"<Node {self.path() or '/'}>"


class Controller:
    """``Sofa.Core.Controller``: recorded as an object of type ``Controller`` (its class name kept)."""

    def __init__(self, *args, **kwargs):
        self.__dict__.setdefault("parent", None)
        self.__dict__["data"] = dict(kwargs)
        self.__dict__["type"] = "Controller"
        self.__dict__["fields"] = {}

    @property
    def name(self) -> str:
        return str(self.data.get("name", type(self).__name__))

    def __setattr__(self, name, value):
        if name == "name":  # a controller naming itself in its __init__ (self.name = "...")
            self.__dict__["data"]["name"] = value.value if isinstance(value, Data) else value
        else:
            object.__setattr__(self, name, value)

    def path(self) -> str:
        return f"{self.parent.path()}/{self.name}" if self.parent is not None else self.name


class Stub:
    """What a scene gets from a module or name the stand-in does not know (``splib3.objectmodel``, a helper of
    another plugin): calls and attributes give stubs, a decorator gives back what it decorates, a class may
    derive from it. The scene's own code runs on; what the stubs would have built is not recorded, and the
    translation lists the stubbed names (:func:`stubbed_module`)."""

    def __init__(self, name: str, used: set):
        self.__dict__.update(_name=name, _used=used)
        used.add(name.split("(")[0])

    def __getattr__(self, attr):
        if attr.startswith("__"):
            raise AttributeError(attr)
        return Stub(f"{self._name}.{attr}", self._used)

    def __setattr__(self, attr, value):
        pass

    def __call__(self, *args, **kwargs):
        if len(args) == 1 and not kwargs and isinstance(args[0], type) or (
                len(args) == 1 and not kwargs and callable(args[0]) and hasattr(args[0], "__code__")):
            return args[0]  # a decorator (@SofaPrefab): the class or function itself
        return Stub(f"{self._name}()", self._used)

    def __mro_entries__(self, bases):
        return (object,)

    def __iter__(self):
        return iter(())

    def __len__(self):
        return 0

    def __bool__(self):
        return False

    def __getitem__(self, i):
        return Stub(f"{self._name}[]", self._used)

    def __repr__(self):
        return f"<stub {self._name}>"


def stubbed_module(name: str, used: set, **attrs) -> types.ModuleType:
    """A module whose missing names are :class:`Stub` s (their names added to ``used``)."""
    m = _module(name, **attrs)
    m.__path__ = []  # a package: its submodules may be imported too
    stub_missing(m, used)
    return m


def stub_missing(module: types.ModuleType, used: set) -> None:
    """Make ``module``'s missing names :class:`Stub` s (``from stlib3.scene import Node`` where the stand-in
    lacks it)."""
    def missing(attr):
        if attr.startswith("__"):
            raise AttributeError(attr)
        return Stub(f"{module.__name__}.{attr}", used)

    module.__getattr__ = missing
    if not hasattr(module, "__path__"):
        module.__path__ = []  # a package: an unknown submodule (stlib3.physics.rigid) reaches the stub finder


class _Vec3(list):
    """splib3.numerics.Vec3: the operations SoftRobots' scenes use."""

    def __init__(self, *args):
        super().__init__([float(x) for x in (args[0] if len(args) == 1 else args)] if args else [0.0, 0.0, 0.0])

    def normalize(self):
        n = math.sqrt(sum(x * x for x in self))
        self[:] = [x / n for x in self]

    def getNorm(self):  # noqa: N802
        return math.sqrt(sum(x * x for x in self))

    def toList(self):  # noqa: N802
        return list(self)

    def rotateFromQuat(self, q):  # noqa: N802
        x, y, z, w = q
        v = np.array(self)
        u = np.array([x, y, z])
        out = 2 * np.dot(u, v) * u + (w * w - np.dot(u, u)) * v + 2 * w * np.cross(u, v)
        self[:] = out.tolist()
        return self

    def translate(self, v):
        self[:] = [a + b for a, b in zip(self, v)]
        return self

    def scale(self, s):
        self[:] = [a * s for a in self]
        return self


class _Quat(list):
    """splib3.numerics.Quat as [x, y, z, w]."""

    def __init__(self, *args):
        super().__init__([float(x) for x in (args[0] if len(args) == 1 else args)] if args else [0, 0, 0, 1.0])

    @staticmethod
    def createFromAxisAngle(axis, angle):  # noqa: N802
        a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
        s = math.sin(angle / 2)
        return _Quat(a[0] * s, a[1] * s, a[2] * s, math.cos(angle / 2))

    @staticmethod
    def createFromEuler(v, *args, **kwargs):  # noqa: N802
        from scipy.spatial.transform import Rotation

        return _Quat(*Rotation.from_euler("xyz", v).as_quat())


def _module(name: str, **attrs) -> types.ModuleType:
    m = types.ModuleType(name)
    m.__dict__.update(attrs)
    return m


def stand_in_modules() -> dict[str, types.ModuleType]:
    noop = lambda *a, **k: None  # noqa: E731
    key = types.SimpleNamespace(plus="+", minus="-", **{c: c for c in "abcdefghijklmnopqrstuvwxyz"},
                                uparrow=19, downarrow=21, leftarrow=18, rightarrow=20, space=" ")
    core = _module("Sofa.Core", Node=Node, Controller=Controller, Object=Object, Data=Data,
                   DataEngine=Controller, ForceField=Controller, Base=Object)
    simulation = _module("Sofa.Simulation", init=noop, initRoot=noop, animate=noop, reset=noop, load=noop,
                         unload=noop)
    helper = _module("Sofa.Helper", msg_info=noop, msg_warning=noop, msg_error=noop, msg_deprecated=noop,
                     System=types.SimpleNamespace(addDataPath=noop, DataRepository=types.SimpleNamespace(
                         addFirstPath=noop, addLastPath=noop)))
    key_module = _module("Sofa.constants.Key", **vars(key))
    constants = _module("Sofa.constants", Key=key_module, KeyCode=key_module)
    sofa = _module("Sofa", Core=core, Simulation=simulation, Helper=helper, constants=constants,
                   msg_info=noop, msg_warning=noop, msg_error=noop, msg_deprecated=noop)
    runtime = _module("SofaRuntime", importPlugin=noop, PluginRepository=types.SimpleNamespace(addFirstPath=noop))
    numerics = _module("splib3.numerics", Vec3=_Vec3, Quat=_Quat, vec3=_module("splib3.numerics.vec3", Vec3=_Vec3),
                       quat=_module("splib3.numerics.quat", Quat=_Quat), sin=math.sin, cos=math.cos, to_radians=math.radians,
                       RigidDof=object)
    animation = _module("splib3.animation", animate=noop, AnimationManager=noop,
                        AnimationManagerController=Controller)
    splib3_constants = _module("splib3.constants", Key=key_module, KeyCode=key_module)
    loaders = _module("splib3.loaders", getLoadingLocation=_loading_location, loadPointListFromFile=_point_list)
    splib3 = _module("splib3", numerics=numerics, animation=animation, constants=splib3_constants, loaders=loaders)
    return {"Sofa": sofa, "Sofa.Core": core, "Sofa.Simulation": simulation, "Sofa.Helper": helper,
            "Sofa.constants": constants, "Sofa.constants.Key": key_module, "Sofa.constants.KeyCode": key_module,
            "SofaRuntime": runtime, "splib3": splib3, "splib3.numerics": numerics,
            "splib3.numerics.vec3": numerics.vec3, "splib3.numerics.quat": numerics.quat,
            "splib3.animation": animation, "splib3.constants": splib3_constants,
            "splib3.constants.Key": key_module, "splib3.loaders": loaders}


def _loading_location(filename, source=None):
    """splib3.loaders.getLoadingLocation: ``filename`` beside the file (or in the folder) ``source``."""
    import os

    if source is None:
        return filename
    if os.path.isfile(source):
        source = os.path.dirname(os.path.abspath(source))
    return os.path.join(source, filename)


def _point_list(path):
    """splib3.loaders.loadPointListFromFile: a JSON list of points."""
    import json

    with open(path) as f:
        return json.load(f)
