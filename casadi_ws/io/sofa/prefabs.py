"""Stand-ins for the Python helpers SoftRobots' tutorials import (STLIB's ``stlib3``, SoftRobots'
``softrobots``): each builds the same nodes and components as the original (read from STLIB and
SoftRobots), with the recorder's classes, so that a scene written with them is recorded as SOFA would build
it. Only the helpers listed in ``docs/sofa.md`` exist; a scene importing another is refused by name.
"""

from __future__ import annotations

import types
from pathlib import Path

from .api import Node

__all__ = ["Prefab", "stand_in_modules"]


class Prefab(Node):
    """``Sofa.Prefab``: a node whose ``prefabParameters`` become data, then ``init()`` builds it."""

    prefabParameters: list = []

    def __init__(self, *args, **kwargs):
        name = kwargs.pop("name", args[0] if args and isinstance(args[0], str) else type(self).__name__)
        attached = kwargs.pop("attachedTo", None) or kwargs.pop("attachedAsAChildOf", None)
        Node.__init__(self, name)
        for p in type(self).prefabParameters:
            self.data[p["name"]] = kwargs.get(p["name"], p.get("default"))
        for k, v in kwargs.items():
            self.data.setdefault(k, v)
        if attached is not None:
            attached.addChild(self)
        self.init()


def _param(name, default):
    return {"name": name, "default": default}


class ElasticMaterialObject(Prefab):
    """stlib3.physics.deformable.ElasticMaterialObject: loader, topology, dofs, UniformMass, corotational
    TetrahedronFEMForceField (method large), solvers."""

    prefabParameters = [_param("volumeMeshFileName", ""), _param("rotation", [0.0, 0.0, 0.0]),
                        _param("translation", [0.0, 0.0, 0.0]), _param("scale", [1.0, 1.0, 1.0]),
                        _param("surfaceMeshFileName", ""), _param("collisionMesh", ""), _param("withConstrain", True),
                        _param("surfaceColor", [1.0, 1.0, 1.0, 1.0]), _param("poissonRatio", 0.3),
                        _param("youngModulus", 18000), _param("totalMass", 1.0), _param("solverName", "")]

    def init(self):
        d = self.data
        if not d["solverName"]:
            self.addObject("EulerImplicitSolver", name="integration")
            self.addObject("SparseLDLSolver", name="solver")
        f = str(d["volumeMeshFileName"])
        kind = "MeshGmshLoader" if f.endswith(".msh") else ("GIDMeshLoader" if f.endswith(".gidmsh") else "MeshVTKLoader")
        self.addObject(kind, name="loader", filename=f, rotation=list(d["rotation"]),
                       translation=list(d["translation"]), scale3d=list(d["scale"]))
        self.addObject("TetrahedronSetTopologyContainer", position="@loader.position", tetras="@loader.tetras",
                       name="container")
        self.addObject("MechanicalObject", template="Vec3", name="dofs")
        self.addObject("UniformMass", totalMass=d["totalMass"], name="mass")
        self.addObject("TetrahedronFEMForceField", template="Vec3", method="large", name="forcefield",
                       poissonRatio=d["poissonRatio"], youngModulus=d["youngModulus"])
        if d["withConstrain"]:
            self.addObject("LinearSolverConstraintCorrection", name="correction")
        if d["collisionMesh"]:
            CollisionMesh(surfaceMeshFileName=d["collisionMesh"], attachedTo=self, name="CollisionModel")
        if d["surfaceMeshFileName"]:
            self.addChild(VisualModel(visualMeshPath=d["surfaceMeshFileName"]))


class VisualModel(Prefab):
    """stlib3.visuals.VisualModel: a surface loader and an OglModel (visual only)."""

    prefabParameters = [_param("visualMeshPath", ""), _param("translation", [0.0, 0.0, 0.0]),
                        _param("rotation", [0.0, 0.0, 0.0]), _param("scale", [1.0, 1.0, 1.0]),
                        _param("color", [1.0, 1.0, 1.0, 1.0])]

    def init(self):
        path = str(self.data["visualMeshPath"])
        self.addObject("MeshOBJLoader" if path.endswith(".obj") else "MeshSTLLoader", name="loader", filename=path)
        self.addObject("OglModel", name="OglModel", src="@loader")


def CollisionMesh(attachedTo=None, surfaceMeshFileName=None, name="collision", **kwargs):  # noqa: N802
    """stlib3.physics.collision.CollisionMesh(attachedTo, surfaceMeshFileName, name, rotation, translation,
    collisionGroup, mappingType): a surface with collision models (listed as not translated)."""
    node = attachedTo.addChild(name)
    node.addObject("MeshSTLLoader" if not str(surfaceMeshFileName).endswith(".obj") else "MeshOBJLoader",
                   name="loader", filename=surfaceMeshFileName)
    node.addObject("MeshTopology", src="@loader")
    node.addObject("MechanicalObject")
    for kind in ("TriangleCollisionModel", "LineCollisionModel", "PointCollisionModel"):
        node.addObject(kind)
    node.addObject("BarycentricMapping")
    return node


def RigidObject(name="RigidObject", surfaceMeshFileName=None, translation=(0.0, 0.0, 0.0),  # noqa: N802
                rotation=(0.0, 0.0, 0.0), uniformScale=1.0, totalMass=1.0, volume=1.0,
                inertiaMatrix=(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0), color=(1.0, 1.0, 1.0, 1.0),
                collisionGroup="", isAStaticObject=False, parent=None, shape=None):
    """stlib3.physics.rigid.RigidObject: a Rigid3 state placed by ``translation``/``rotation``, a mass, an
    integrator unless ``isAStaticObject``, a collision child (the surface mesh, scaled by ``uniformScale``) and a
    visual one. ``shape`` (Cube, Sphere, Floor) says what SOFA's own mesh file is, which is not shipped here."""
    node = Node(name)
    if parent is not None:
        parent.addChild(node)
    node.addObject("MechanicalObject", name="mstate", template="Rigid3", translation2=list(translation),
                   rotation2=list(rotation), showObjectScale=uniformScale)
    node.addObject("UniformMass", name="mass", vertexMass=[totalMass, volume, list(inertiaMatrix)])
    if not isAStaticObject:
        node.addObject("EulerImplicitSolver")
        node.addObject("CGLinearSolver", iterations=25, tolerance=1e-5, threshold=1e-5)
    node.__dict__["rigid"] = {"static": bool(isAStaticObject), "shape": shape, "scale": float(uniformScale),
                              "translation": list(translation), "rotation": list(rotation)}
    if surfaceMeshFileName is not None:
        col = node.addChild("collision")
        col.addObject("MeshOBJLoader", name="loader", filename=surfaceMeshFileName, triangulate=True,
                      scale=uniformScale)
        col.addObject("MeshTopology", src="@loader")
        col.addObject("MechanicalObject")
        for kind in ("TriangleCollisionModel", "LineCollisionModel", "PointCollisionModel"):
            col.addObject(kind, group=collisionGroup, **({"moving": False, "simulated": False} if isAStaticObject else {}))
        col.addObject("RigidMapping")
        node.addChild(VisualModel(name="visual", visualMeshPath=surfaceMeshFileName, color=list(color),
                                  scale=[uniformScale] * 3))
        node.visual.addObject("RigidMapping")
    return node


def _rigid(shape, mesh):
    def make(node, **kwargs):
        kwargs.setdefault("name", shape.capitalize())
        return RigidObject(parent=node, surfaceMeshFileName=mesh, shape=shape, **kwargs)
    make.__name__ = shape.capitalize()
    make.__doc__ = f"stlib3.physics.rigid.{make.__name__}: a RigidObject on SOFA's {mesh}."
    return make


Cube, Sphere, Floor = _rigid("cube", "mesh/cube.obj"), _rigid("sphere", "mesh/ball.obj"), _rigid("floor", "mesh/floor.obj")


def Rigidify(targetObject, sourceObject, groupIndices, frames=None, name=None):  # noqa: N802, N803
    """stlib3.physics.mixedmaterial.Rigidify: groups of the body's points made rigid. The stand-in builds the
    nodes the scene goes on to use (``RigidParts``, ``DeformableParts``) and marks the body with its groups,
    which the translation lists (the groups stay elastic in casadi-ws)."""
    node = targetObject.addChild(name or sourceObject.name)
    node.__dict__["rigidify_of"] = sourceObject
    free = node.addChild("DeformableParts")
    free.addObject("MechanicalObject", template="Vec3", name="dofs")
    rigid = node.addChild("RigidParts")
    rigid.addObject("MechanicalObject", template="Rigid3", name="dofs", position=[list(f) for f in frames or []])
    points = rigid.addChild("RigidifiedParticules")
    points.addObject("MechanicalObject", template="Vec3", name="dofs")
    points.addObject("RigidMapping", name="mapping", globalToLocalCoords=True)
    for kind in ("solver", "integration", "correction"):
        obj = sourceObject.getObject(kind)
        if obj is not None:
            sourceObject.removeObject(obj)
    sourceObject.addObject("SubsetMultiMapping", name="mapping", template="Vec3,Vec3")
    sourceObject.__dict__["rigidified"] = [list(map(int, g)) for g in groupIndices]
    return node


def FixedBox(applyTo=None, atPositions=(-1.0, -1.0, -1.0, 1.0, 1.0, 1.0), name="FixedBox", doVisualization=False,  # noqa: N802
             position=None, constraintStrength=1e12, doRecomputeDuringSimulation=False):
    """stlib3.physics.constraints.FixedBox: a child node with a BoxROI and stiff RestShapeSprings."""
    c = applyTo.addChild(name)
    c.addObject("BoxROI", name="BoxROI", box=list(atPositions))
    c.addObject("RestShapeSpringsForceField", points="@BoxROI.indices", stiffness=constraintStrength)
    return c


def PullingCable(attachedTo=None, name="Cable", cableGeometry=((1.0, 0.0, 0.0), (0.0, 0.0, 0.0)),  # noqa: N802
                 rotation=(0.0, 0.0, 0.0), translation=(0.0, 0.0, 0.0), uniformScale=1.0, pullPointLocation=None,
                 initialValue=0.0, valueType="displacement"):
    """softrobots.actuators.PullingCable: a cable node (its points placed by the MechanicalObject's
    rotation/translation/scale)."""
    cable = attachedTo.addChild(name)
    cable.addObject("MechanicalObject", position=[list(p) for p in cableGeometry], rotation=list(rotation),
                    translation=list(translation), scale=uniformScale)
    extra = {"pullPoint": list(pullPointLocation), "hasPullPoint": True} if pullPointLocation is not None else \
        {"hasPullPoint": False}
    cable.addObject("CableConstraint", indices=list(range(len(cableGeometry))), value=initialValue,
                    valueType=valueType, **extra)
    cable.addObject("BarycentricMapping", name="Mapping")
    return cable


def PneumaticCavity(surfaceMeshFileName=None, attachedAsAChildOf=None, attachedTo=None, name="PneumaticCavity",  # noqa: N802
                    rotation=(0.0, 0.0, 0.0), translation=(0.0, 0.0, 0.0), uniformScale=1, initialValue=0,
                    valueType="volumeGrowth"):
    """softrobots.actuators.PneumaticCavity: a surface loader, topology, SurfacePressureConstraint."""
    node = attachedTo if attachedTo is not None else attachedAsAChildOf.addChild(name)
    kind = "MeshOBJLoader" if str(surfaceMeshFileName).endswith(".obj") else "MeshSTLLoader"
    node.addObject(kind, name="MeshLoader", filename=surfaceMeshFileName, rotation=list(rotation),
                   translation=list(translation), scale=uniformScale)
    node.addObject("MeshTopology", name="topology", src="@MeshLoader")
    node.addObject("MechanicalObject", src="@topology")
    node.addObject("SurfacePressureConstraint", value=initialValue, valueType=valueType)
    node.addObject("BarycentricMapping", name="Mapping")
    return node


def _scene(root, gravity=(0.0, -9.81, 0.0), dt=0.01, plugins=(), repositoryPaths=(), iterative=True,  # noqa: N803
           **kwargs):
    """stlib3.scene.Scene / MainHeader: gravity, dt, a VisualStyle; Scene's add* methods add its nodes."""
    root.data["gravity"] = list(gravity)
    root.data["dt"] = dt
    root.addObject("VisualStyle", name="VisualStyle")

    def child(name):  # STLIB's Scene keeps one of each (a scene may ask twice)
        node = root.getChild(name)
        if node is None:
            node = root.addChild(name)
            if name == "Settings":  # the mouse's spring, which tutorials tune (Settings.mouseButton.stiffness)
                node.addObject("AttachBodyButtonSetting", name="mouseButton", stiffness=10)
        return node

    def add_solver(node):
        node.addObject("EulerImplicitSolver", name="TimeIntegrationSchema")
        node.addObject("CGLinearSolver" if iterative else "SparseLDLSolver", name="LinearSolver")
        return node

    def add_simulation(*a, **k):
        sim = child("Simulation")
        if not sim.objects:
            add_solver(sim)
        return sim

    def add_main_header(*a, **k):
        child("Settings"), child("Modelling"), add_simulation()
        return root

    root.__dict__.update(addMainHeader=add_main_header, addSettings=lambda *a, **k: child("Settings"),
                         addModelling=lambda *a, **k: child("Modelling"), addSimulation=add_simulation,
                         addSolver=add_solver, addContact=lambda *a, **k: ContactHeader(root, *a, **k))
    return root


def ContactHeader(applyTo, alarmDistance=None, contactDistance=None, frictionCoef=0.0, **kwargs):  # noqa: N802, N803
    """stlib3.scene.ContactHeader: the collision pipeline (listed as not translated)."""
    for kind in ("CollisionPipeline", "BruteForceBroadPhase", "BVHNarrowPhase", "RuleBasedContactManager",
                 "LocalMinDistance"):
        applyTo.addObject(kind)
    return applyTo


VENDOR = Path(__file__).resolve().parent / "vendor"
"""SoftRobots' robot parts (``softrobots.parts.finger``, ``.bunny``), copied unchanged under their licence."""


def stand_in_modules(base: dict) -> dict:
    """The stlib3 and softrobots modules (and ``Sofa.Prefab``), added to the recorder's stand-ins."""
    base["Sofa"].Prefab = Prefab
    base["Sofa.Core"].Prefab = Prefab

    def module(name, **attrs):
        m = types.ModuleType(name)
        m.__dict__.update(attrs)
        return m

    deformable = module("stlib3.physics.deformable", ElasticMaterialObject=ElasticMaterialObject)
    constraints = module("stlib3.physics.constraints", FixedBox=FixedBox)
    collision = module("stlib3.physics.collision", CollisionMesh=CollisionMesh)
    rigid = module("stlib3.physics.rigid", RigidObject=RigidObject, Cube=Cube, Sphere=Sphere, Floor=Floor)
    mixed = module("stlib3.physics.mixedmaterial", Rigidify=Rigidify)
    physics = module("stlib3.physics", deformable=deformable, constraints=constraints, collision=collision,
                     rigid=rigid, mixedmaterial=mixed)
    scene = module("stlib3.scene", Scene=_scene, MainHeader=_scene, ContactHeader=ContactHeader)
    visuals = module("stlib3.visuals", VisualModel=VisualModel)
    stlib3 = module("stlib3", physics=physics, scene=scene, visuals=visuals)
    actuators = module("softrobots.actuators", PullingCable=PullingCable, PneumaticCavity=PneumaticCavity)
    # SoftRobots' own parts (vendor/NOTICE.md): a package whose submodules the import system finds in the
    # vendored folder and runs against these stand-ins
    parts = module("softrobots.parts", __path__=[str(VENDOR / "softrobots" / "parts")])
    softrobots = module("softrobots", actuators=actuators, parts=parts)
    return {"softrobots.parts": parts, "stlib3": stlib3, "stlib3.physics": physics, "stlib3.physics.deformable": deformable,
            "stlib3.physics.constraints": constraints, "stlib3.physics.collision": collision, "stlib3.physics.rigid": rigid,
            "stlib3.physics.mixedmaterial": mixed,
            "stlib3.scene": scene, "stlib3.visuals": visuals, "softrobots": softrobots,
            "softrobots.actuators": actuators}
