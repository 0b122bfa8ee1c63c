"""Synthetic demonstration generators (the paper's MOVE, ROTATE, CLEAN, PAINT)."""

from cgda_jax.datasets.synthetic import (
    ACTIONS as ACTIONS,
    ARM_FEATURES as ARM_FEATURES,
    CLEAN_CENTRE_M as CLEAN_CENTRE_M,
    MARKER_FEATURES as MARKER_FEATURES,
    SPATIAL_FEATURES as SPATIAL_FEATURES,
    clean_circle_demos as clean_circle_demos,
    paint_ramp as paint_ramp,
    select_features as select_features,
    synthetic_actions as synthetic_actions,
    synthetic_arm_actions as synthetic_arm_actions,
)

__all__ = [
    "ACTIONS",
    "ARM_FEATURES",
    "CLEAN_CENTRE_M",
    "MARKER_FEATURES",
    "SPATIAL_FEATURES",
    "clean_circle_demos",
    "paint_ramp",
    "select_features",
    "synthetic_actions",
    "synthetic_arm_actions",
]
