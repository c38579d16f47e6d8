"""Structure descriptions, YAML model files, exact symbolic derivation, compiled numeric models, bearing stiffness."""

from cappe.model.bearing import AngularContactBearing, BearingState
from cappe.model.flexible import FlexibleBody, FlexibleDamping, InterfaceNode, NodeLine
from cappe.model.loader import FORMAT, load_model, structure_from_mapping
from cappe.model.numeric import NumericModel, compile_model
from cappe.model.structure import (
    GROUND,
    Axis,
    Body,
    Input,
    Output,
    Parameter,
    Sensor,
    Spin,
    StiffnessDampingElement,
    Structure,
    StructureBuilder,
)
from cappe.model.symbolic import SymbolicModel, derive
from cappe.parallel import ship_once

# a Dask executor sends a compiled model to each worker once, not with every map (its caches stay here)
ship_once(NumericModel, caches=("_pattern_cache", "_source_row_cache", "_sensor_matrix_cache", "_sparse_cache",
                                "_safe_coefficient"))

__all__ = [
    "FORMAT",
    "GROUND",
    "AngularContactBearing",
    "Axis",
    "BearingState",
    "Body",
    "FlexibleBody",
    "FlexibleDamping",
    "Input",
    "InterfaceNode",
    "NodeLine",
    "NumericModel",
    "Output",
    "Parameter",
    "Sensor",
    "Spin",
    "StiffnessDampingElement",
    "Structure",
    "StructureBuilder",
    "SymbolicModel",
    "compile_model",
    "derive",
    "load_model",
    "structure_from_mapping",
]
