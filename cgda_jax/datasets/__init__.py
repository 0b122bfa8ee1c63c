"""Synthetic demonstration generators (the paper's MOVE, ROTATE, CLEAN, PAINT; object
effects: a pushed box, a turned valve)."""

from cgda_jax.datasets.objects import (
    MOVE_BOX_END as MOVE_BOX_END,
    MOVE_BOX_START as MOVE_BOX_START,
    OBJECT_ACTIONS as OBJECT_ACTIONS,
    OBJECT_FEATURES as OBJECT_FEATURES,
    VALVE_END as VALVE_END,
    VALVE_START as VALVE_START,
    move_box_demos as move_box_demos,
    object_actions as object_actions,
    rotate_valve_demos as rotate_valve_demos,
)
from cgda_jax.datasets.synthetic import (
    ACTIONS as ACTIONS,
    ARM_FEATURES as ARM_FEATURES,
    CLEAN_CENTRE_M as CLEAN_CENTRE_M,
    MARKER_FEATURES as MARKER_FEATURES,
    SPATIAL_FEATURES as SPATIAL_FEATURES,
    SyntheticSequence as SyntheticSequence,
    clean_circle_demos as clean_circle_demos,
    distractor_names as distractor_names,
    paint_ramp as paint_ramp,
    select_features as select_features,
    synthetic_actions as synthetic_actions,
    synthetic_arm_actions as synthetic_arm_actions,
    synthetic_sequence as synthetic_sequence,
)

__all__ = [
    "ACTIONS",
    "ARM_FEATURES",
    "CLEAN_CENTRE_M",
    "MARKER_FEATURES",
    "MOVE_BOX_END",
    "MOVE_BOX_START",
    "OBJECT_ACTIONS",
    "OBJECT_FEATURES",
    "SPATIAL_FEATURES",
    "SyntheticSequence",
    "VALVE_END",
    "VALVE_START",
    "clean_circle_demos",
    "distractor_names",
    "move_box_demos",
    "object_actions",
    "rotate_valve_demos",
    "paint_ramp",
    "select_features",
    "synthetic_actions",
    "synthetic_arm_actions",
    "synthetic_sequence",
]
