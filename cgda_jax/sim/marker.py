"""The marker: the point of the robot whose position the scenes read.

A marker is a site of the model (``"tool_tip"`` or ``{"site": "tool_tip"}``), or a
point fixed on a body, ``{"body": "hand", "pos": [x, y, z]}`` (metres in the body's
frame), for a model without a site where the tool is.  For a point on a body the
`cgda_jax.sim.robot.Robot` adds a site `MARKER_POINT_SITE` there to its model (and to
every model rebuilt from its ``MjSpec``, dynamic mode's included), so the chain
kinematics, the MJX kinematics and the physics sensors all read one site.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import mujoco
import numpy as np

__all__ = ["MARKER_POINT_SITE", "Marker", "check_marker_point", "marker_spec",
           "with_marker_point"]

#: The site a `Robot` adds to its model for a marker given as a point on a body.
MARKER_POINT_SITE = "cgda_marker_point"

#: A marker: a site's name, ``{"site": name}`` or ``{"body": name, "pos": [x, y, z]}``.
Marker = str | Mapping[str, Any]


def marker_spec(marker: Marker) -> tuple[str | None, str | None, tuple[float, ...]]:
    """``(site, body, pos)`` of a marker (see `Marker`): a site's name with no body,
    or a body's name and the point's position (3,) in that body's frame [m].

    Raises:
        ValueError: neither or both of site and body, an unknown key, a position
            that is not 3 finite numbers (the message starts with "marker").
    """
    if isinstance(marker, str):
        return marker, None, (0.0, 0.0, 0.0)
    if not isinstance(marker, Mapping):
        raise ValueError(f"marker {marker!r}: give a site's name or a table "
                         "{body = NAME, pos = [x, y, z]} / {site = NAME}")
    unknown = sorted(set(marker) - {"site", "body", "pos"})
    if unknown:
        raise ValueError(f"marker {dict(marker)}: unknown key(s) {unknown}; it takes "
                         "'site', or 'body' and 'pos'")
    site, body = marker.get("site"), marker.get("body")
    if (site is None) == (body is None):
        raise ValueError(f"marker {dict(marker)}: give either 'site' (a site's name) "
                         "or 'body' (a body's name, with 'pos' in its frame)")
    if site is not None:
        if "pos" in marker:
            raise ValueError(f"marker {dict(marker)}: 'pos' goes with 'body', not "
                             "with a site (a site has its own position)")
        return str(site), None, (0.0, 0.0, 0.0)
    pos = marker.get("pos", (0.0, 0.0, 0.0))
    try:
        pos = tuple(float(v) for v in pos)
    except (TypeError, ValueError):
        raise ValueError(f"marker pos {pos!r}: expected 3 numbers [x, y, z] in "
                         "metres") from None
    if len(pos) != 3 or not all(math.isfinite(v) for v in pos):
        raise ValueError(f"marker pos {list(pos)}: expected 3 finite numbers "
                         "[x, y, z] in metres")
    return None, str(body), pos


def with_marker_point(factory: Callable[[], mujoco.MjSpec], body: str,
                      pos: tuple[float, ...], source: str
                      ) -> Callable[[], mujoco.MjSpec]:
    """``factory`` whose specs carry the site `MARKER_POINT_SITE` at ``pos`` on
    ``body``."""

    def with_site() -> mujoco.MjSpec:
        spec = factory()
        parent = spec.body(body)
        if parent is None:
            names = [b.name for b in spec.bodies]
            raise KeyError(f"marker body {body!r} not found in {source}; it has "
                           f"{names}")
        site = parent.add_site(name=MARKER_POINT_SITE, pos=list(pos))
        site.group = 5  # a point, not part of the robot's look
        return spec

    return with_site


def check_marker_point(mj_model: mujoco.MjModel, body: str, pos, source: str) -> None:
    """The model's `MARKER_POINT_SITE` is at ``pos`` on ``body``."""
    sid = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_SITE, MARKER_POINT_SITE)
    bid = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_BODY, body)
    if bid < 0 or int(mj_model.site_bodyid[sid]) != bid or not np.allclose(
            mj_model.site_pos[sid], pos, atol=1e-12):
        raise ValueError(f"{source}: its site {MARKER_POINT_SITE!r} is not the marker "
                         f"point {list(pos)} on body {body!r} (a name reserved for it)")
