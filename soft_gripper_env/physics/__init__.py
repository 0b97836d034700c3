"""The physics core: discrete elastic rod fingers, force models and implicit time stepping.

Pure NumPy/SciPy with Numba-compiled kernels; it never imports gymnasium, torch or stable-baselines3.
"""

from .config import (
    ELASTOSIL_MA_4601,
    PAPER_DEFECTIVE_DRAG,
    SOFT_TRANSLUCENT_SILICONE,
    WATER_VISCOSITY,
    FingerDesign,
    GripperDesign,
    Material,
    NewtonSettings,
    Scene,
    cantilever_scene,
    linear_taper,
    paper_finger,
    paper_scene,
)
from .contact import PAPER_BALL, PENETRATION_TOLERANCE, Capsule, ContactReport, ContactSettings, Sphere
from .discretization import Discretization
from .forces import Buoyancy, ForceModel, Gravity, MassProportionalDamping, StepContext, StokesDrag
from .hydrodynamics import WATER_DENSITY, AddedMass, Current, MorisonDrag, fluid_forces
from .simulator import NATURAL_CURVATURE_LIMIT, RodState, Simulator, StepResult, Trajectory, run_ramp

__all__ = [
    "ELASTOSIL_MA_4601", "PAPER_DEFECTIVE_DRAG", "SOFT_TRANSLUCENT_SILICONE", "WATER_VISCOSITY", "FingerDesign",
    "GripperDesign", "Material", "NewtonSettings", "Scene", "cantilever_scene", "linear_taper", "paper_finger",
    "paper_scene", "Discretization", "Buoyancy", "ForceModel", "Gravity", "MassProportionalDamping", "StokesDrag",
    "RodState", "Simulator", "StepResult", "Trajectory", "run_ramp", "StepContext", "WATER_DENSITY", "AddedMass",
    "Current", "MorisonDrag", "fluid_forces", "PAPER_BALL", "PENETRATION_TOLERANCE", "ContactReport",
    "ContactSettings", "Sphere", "Capsule", "NATURAL_CURVATURE_LIMIT",
]
