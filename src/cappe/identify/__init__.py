"""From measurements to experimental models: excitation signals, FRF estimation, black-box models (ARX, ARMAX,
OE, BJ) with order selection and pruning, frequency-domain rational fits, modal extraction (LSCF / LSFD with
stabilization diagrams) and rigid-body motion reconstruction."""

from cappe.identify._lscf import PoleSelection, StabilizationDiagram, lscf_poles, select_poles, stabilization_diagram
from cappe.identify._lsfd import ModalExtraction, ModalFit, extract_modes, lsfd
from cappe.identify._rigid_body import (
    NINE_ACCELEROMETER_LABELS,
    RIGID_BODY_DOFS,
    AccelerometerLayout,
    BodyGeometry,
    MotionConfidence,
    RigidBodyMotion,
    accelerometer_matrix,
    body_geometry,
    integrate_acceleration,
    model_rigid_body_motion,
    motion_confidence,
    nine_accelerometer_layout,
    reconstruct_rigid_body_motion,
    solve_nine_accelerometers,
)

__all__ = [
    "NINE_ACCELEROMETER_LABELS",
    "RIGID_BODY_DOFS",
    "AccelerometerLayout",
    "BodyGeometry",
    "MotionConfidence",
    "RigidBodyMotion",
    "accelerometer_matrix",
    "body_geometry",
    "integrate_acceleration",
    "model_rigid_body_motion",
    "motion_confidence",
    "nine_accelerometer_layout",
    "reconstruct_rigid_body_motion",
    "solve_nine_accelerometers",
    "ModalExtraction",
    "ModalFit",
    "PoleSelection",
    "StabilizationDiagram",
    "extract_modes",
    "lscf_poles",
    "lsfd",
    "select_poles",
    "stabilization_diagram",
]
