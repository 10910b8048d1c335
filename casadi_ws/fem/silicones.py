"""Named silicones: published strain-energy fits, each with its source.

``material: {name: ecoflex-00-30}`` in a problem file starts from an entry; any key given beside the name
(a constant, ``bulk_modulus``, ``density``) overrides the entry's. Constants are in Pa, in Abaqus'
convention (:mod:`casadi_ws.fem.materials`). The entries give no compressibility: the published fits assume
incompressible rubber, and the bulk modulus is a modelling choice (``bulk_modulus``, ``d1`` or
``poisson_ratio``; by default the small-strain nu = 0.45, see docs/problem-format.md).
"""

from __future__ import annotations

__all__ = ["SILICONES"]

SILICONES: dict[str, dict] = {
    "ecoflex-00-30": {
        "model": "yeoh", "c10": 1.7e4, "c20": -2.0e2, "c30": 2.3e1, "density": 1070.0,
        "source": "Yeoh fit of Steck et al. 2019, 'Mechanical responses of Ecoflex silicone rubber: compressible "
                  "and incompressible behaviors', J. Appl. Polym. Sci. 136(5):47025; as entered in "
                  "github.com/Nicholas-A-Thompson/Curved-FREEs-FEA free_fea/abaqus_setup.py "
                  "('Ecoflex 00-30 (Yeoh, Steck 2019)', MPa) and in SOROTOKI. Density: Smooth-On's "
                  "technical bulletin (specific gravity 1.07)."},
    "ecoflex-00-50": {
        "model": "yeoh", "c10": 1.9e4, "c20": 9.0e2, "c30": -4.75, "density": 1070.0,
        "source": "Yeoh fit of Kulkarni et al. 2015; as entered in github.com/Nicholas-A-Thompson/Curved-FREEs-FEA "
                  "free_fea/abaqus_setup.py ('Ecoflex 00-50 (Yeoh, Kulkarni 2015)', MPa). The negative C30 stops "
                  "the stiffening near a uniaxial stretch of 12. Density: Smooth-On (specific gravity 1.07)."},
    "dragon-skin-10": {
        "model": "yeoh", "c10": 3.6e4, "c20": 2.5e2, "c30": 2.3e1, "density": 1070.0,
        "source": "Yeoh fit of Caasenbrood et al. 2020 (SOROTOKI, github.com/BJCaasenbrood/SorotokiCode "
                  "+preset/+material/Dragonskin10.m: C1 36e-3, C2 0.25e-3, C3 0.023e-3 MPa, density 1070 kg/m^3); "
                  "the same constants in Curved-FREEs-FEA ('DS10 (Yeoh, Caasenbrood 2020)')."},
    "dragon-skin-30": {
        "model": "yeoh", "c10": 9.6e4, "c20": 9.5e3, "c30": 0.0, "density": 1080.0,
        "source": "Yeoh fit of Chen et al. 2018; as entered in github.com/Nicholas-A-Thompson/Curved-FREEs-FEA "
                  "free_fea/abaqus_setup.py ('DS30 (Yeoh, Chen 2018)', MPa). Density: Smooth-On (specific "
                  "gravity 1.08)."},
    "elastosil-m4601": {
        "model": "yeoh", "c10": 1.1e5, "c20": 2.0e4, "c30": 0.0, "density": 1130.0,
        "source": "Yeoh fit used for Elastosil M4601 A/B by Polygerinos et al. 2015 ('Modeling of soft "
                  "fiber-reinforced bending actuators', IEEE T-RO 31(3)) and Connolly et al. (Soft Robotics "
                  "Toolkit); as entered in github.com/abd-alaz/spiral-sensors SingleMuscle.py "
                  "(YEOH table 0.11, 0.02, 0 MPa; density 1.13e-9 t/mm^3)."},
}
"""name -> {model, constants (Pa), density (kg/m^3), source}. The constants were read from the simulation
code named in each source, which cites the publication; they were not checked against the publications'
tables here (docs/problem-format.md says so)."""
