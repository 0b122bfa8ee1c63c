"""Synthetic demonstrations of the paper's four actions (MOVE, ROTATE, CLEAN, PAINT).

The 2015 paper (section 4.1) tracked a coloured marker with a Kinect while a person
demonstrated four actions seven times each, and also tracked the person's arm points
(section 4.2). The recordings were never published, so this module synthesizes
demonstrations with the stated geometry and a human's variability: every repetition
has its own speed, duration, pauses at the start and end, a hesitation in the middle,
sensor noise, a slightly different place on the desk and a different arm posture for
the same effect on the object.

Units follow the sensor: marker position in millimetres in the camera frame (X right,
Y away from the demonstrator along the desk, Z depth from the camera, which looks
down at the desk), blob area in pixels, hue in OpenCV units [0, 180), saturation and
value in [0, 255], angle in degrees. Arm points are in metres in the same frame.

Everything here runs on the host with ``np.random.default_rng(seed)``: these are
fixtures, not part of any jitted path.

References:
    Morante et al., "Humanoid Robot Imitation through Continuous Goal-Directed
    Actions: An Evolutionary Approach", Advanced Robotics 2015, sections 4.1-4.2.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from cgda_jax.data import Demonstration
from cgda_jax.numerics import min_jerk_np

ACTIONS: tuple[str, ...] = ("MOVE", "ROTATE", "CLEAN", "PAINT")
MARKER_FEATURES: tuple[str, ...] = (
    "X", "Y", "Z", "area", "hue", "saturation", "value", "angle",
)
SPATIAL_FEATURES: tuple[str, ...] = ("X", "Y", "Z")
ARM_POINTS: tuple[str, ...] = ("hand", "wrist", "elbow", "shoulder")
ARM_FEATURES: tuple[str, ...] = tuple(
    f"{p}_{c}" for p in ARM_POINTS for c in ("x", "y", "z")
)

MOVE_LENGTH_MM = 300.0  # "marker displacement of 30 cm in one straight direction"
ROTATE_ANGLE_DEG = 90.0  # "rotation over the centre of mass, on one axis, of 90 degrees"
CLEAN_DIAMETER_MM = 300.0  # "circumference of 30 cm of diameter (1 revolution)"

# Where on the desk each action is demonstrated (mm, camera frame) and how long it
# takes on average (s). The person used different spots for different actions.
_PLACE_MM = {
    "MOVE": np.array([-200.0, 0.0, 880.0]),
    "ROTATE": np.array([150.0, 120.0, 900.0]),
    "CLEAN": np.array([0.0, -20.0, 890.0]),
    "PAINT": np.array([220.0, -180.0, 870.0]),
}
_DURATION_S = {"MOVE": 4.0, "ROTATE": 4.0, "CLEAN": 7.0, "PAINT": 9.0}

_AREA_PX = 2400.0  # blob area of the marker at the reference depth
_REF_DEPTH_MM = 880.0
_HUE_GREEN, _HUE_BLUE = 60.0, 118.0  # marker colour before / after painting
# tracking noise (standard deviation) of each marker feature, in its unit
_MARKER_NOISE = np.array([3.0, 3.0, 4.0, 20.0, 1.5, 4.0, 4.0, 1.5])
_UPPER_ARM_M, _FOREARM_M = 0.30, 0.26
_GRAVITY = np.array([0.0, 0.0, 1.0])  # the camera looks down: +Z points to the floor


@dataclasses.dataclass(frozen=True)
class _Repetition:
    """One repetition on the host: sample times (T,), marker (T, 8), arm (T, 12),
    progress of the motion (T,) in [0, 1] (0 before it starts, 1 once it ends)."""

    times: np.ndarray
    marker: np.ndarray
    arm: np.ndarray
    progress: np.ndarray


def repetition_progress(rng: np.random.Generator, n: int, rate_hz: float,
                        duration: float):
    """Progress p (T,) in [0, 1] of one repetition with pauses and a hesitation.

    The person waits a moment before and after the action, and halfway through may
    slow down or stop briefly; the motion itself follows a minimum-jerk profile.
    """
    pre, post = rng.uniform(0.2, 0.8, size=2)
    t = np.arange(n) / rate_hz
    s = np.clip((t - pre) / duration, 0.0, 1.0)
    # Random monotone time warp: a hesitation somewhere in the middle.
    knots = np.sort(rng.uniform(0.2, 0.8, size=2))
    warped_at_knots = knots + rng.uniform(-0.08, 0.08, size=2)
    warped_at_knots = np.clip(np.sort(warped_at_knots), 0.05, 0.95)
    s = np.interp(s, np.r_[0.0, knots, 1.0], np.r_[0.0, warped_at_knots, 1.0])
    return min_jerk_np(s), pre + duration + post


def _sample_count(rng: np.random.Generator, action: str, rate_hz: float):
    """Duration of the motion (s) and sample count, with the pauses included."""
    duration = _DURATION_S[action] * rng.uniform(0.75, 1.35)
    total = duration + 1.6  # at most 0.8 s of pause on either side
    return duration, int(round(total * rate_hz))


def _elbow(
    shoulder: np.ndarray, wrist: np.ndarray, swivel: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Two-link arm: elbow (T, 3) for a shoulder and wrist (T, 3) and a swivel angle (T,).

    Where the wrist is out of reach, the shoulder is moved towards it (the person
    leans forward); the adjusted shoulder (T, 3) is returned with the elbow.
    """
    reach = 0.97 * (_UPPER_ARM_M + _FOREARM_M)
    v = wrist - shoulder
    d = np.linalg.norm(v, axis=-1, keepdims=True)
    lean = np.clip(d - reach, 0.0, None)
    shoulder = shoulder + lean * v / d
    v = wrist - shoulder
    d = np.linalg.norm(v, axis=-1, keepdims=True)
    u = v / d
    a = (_UPPER_ARM_M**2 - _FOREARM_M**2 + d**2) / (2.0 * d)
    r = np.sqrt(np.clip(_UPPER_ARM_M**2 - a**2, 0.0, None))
    e1 = _GRAVITY - (u @ _GRAVITY)[:, None] * u
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(u, e1)
    c, s = np.cos(swivel)[:, None], np.sin(swivel)[:, None]
    return shoulder + a * u + r * (c * e1 + s * e2), shoulder


def _repetition(
    rng: np.random.Generator, action: str, rate_hz: float
) -> _Repetition:
    """Marker features and arm points of one repetition of ``action``."""
    duration, n = _sample_count(rng, action, rate_hz)
    p, _ = repetition_progress(rng, n, rate_hz, duration)
    times = np.arange(n) / rate_hz
    place = _PLACE_MM[action] + rng.normal(0.0, [12.0, 12.0, 6.0])

    pos = np.tile(place, (n, 1))
    angle = np.full(n, rng.uniform(-10.0, 10.0))
    coverage = np.zeros(n)
    hand_offset = np.zeros((n, 3))  # hand tip relative to the marker, metres
    if action == "MOVE":
        heading = rng.normal(0.0, np.deg2rad(6.0))
        direction = np.array([np.cos(heading), np.sin(heading), 0.0])
        pos = place + MOVE_LENGTH_MM * p[:, None] * direction
    elif action == "ROTATE":
        angle = angle + ROTATE_ANGLE_DEG * p
        # The fingers hold the marker's edge, which turns about its centre.
        phi = np.deg2rad(angle) + rng.uniform(-0.5, 0.5)
        hand_offset = 0.04 * np.stack([np.cos(phi), np.sin(phi), 0 * phi], -1)
    elif action == "CLEAN":
        start = rng.uniform(-0.3, 0.3)
        theta = start + 2.0 * np.pi * p
        r = CLEAN_DIAMETER_MM / 2.0
        circle = np.stack([np.cos(theta), np.sin(theta), 0 * theta], -1)
        pos = place + r * (circle - circle[:1])  # start on the circle at `place`
    elif action == "PAINT":
        coverage = rng.uniform(0.9, 0.97) * p
        # The pen scribbles over the marker while it stays in place.
        freq = rng.uniform(1.5, 2.5)
        w = 2.0 * np.pi * freq * times
        hand_offset = 0.025 * np.stack([np.sin(w), np.sin(1.7 * w), 0 * w], -1)
        hand_offset *= ((p > 0.0) & (p < 1.0))[:, None]
    else:  # pragma: no cover - guarded by the caller
        raise ValueError(f"unknown action {action!r}; expected one of {ACTIONS}")

    depth = pos[:, 2]
    area = _AREA_PX * (_REF_DEPTH_MM / depth) ** 2
    hue = _HUE_GREEN + (_HUE_BLUE - _HUE_GREEN) * coverage
    saturation = 210.0 - 50.0 * coverage
    value = 190.0 - 95.0 * coverage
    marker = np.column_stack([pos, area, hue, saturation, value, angle])
    marker = marker + rng.normal(0.0, _MARKER_NOISE, size=marker.shape)

    arm = _arm_points(rng, pos / 1000.0, hand_offset, p)
    return _Repetition(times=times, marker=marker, arm=arm, progress=p)


def _arm_points(
    rng: np.random.Generator, marker_m: np.ndarray, hand_offset: np.ndarray,
    p: np.ndarray,
) -> np.ndarray:
    """Hand tip, wrist, elbow and shoulder (T, 12) of a person acting on the marker.

    The posture changes between repetitions (where the person stands, how the
    hand grips, how high the elbow is) and drifts during one, as a human's would.
    """
    n = marker_m.shape[0]
    grip = np.array([0.0, -0.02, -0.05]) + rng.normal(0.0, 0.01, 3)
    hand = marker_m + grip + hand_offset
    wrist_dir = np.array([0.05, -0.9, -0.4]) + rng.normal(0.0, 0.15, 3)
    wrist = hand + 0.09 * wrist_dir / np.linalg.norm(wrist_dir)
    shoulder = np.array([0.15, -0.42, 0.45]) + rng.normal(0.0, [0.05, 0.04, 0.03])
    shoulder = np.tile(shoulder, (n, 1))
    swivel = rng.uniform(-0.7, 0.7) + 0.25 * np.sin(
        2.0 * np.pi * (rng.uniform(0.3, 1.0) * p + rng.uniform())
    )
    elbow, shoulder = _elbow(shoulder, wrist, swivel)
    arm = np.column_stack([hand, wrist, elbow, shoulder])
    return arm + rng.normal(0.0, 0.004, size=arm.shape)


def check_repetitions(n_repetitions: int, rate_hz: float) -> None:
    """``n_repetitions`` is a positive integer and ``rate_hz`` positive."""
    if int(n_repetitions) != n_repetitions or n_repetitions < 1:
        raise ValueError(f"n_repetitions must be a positive integer, got {n_repetitions!r}")
    if not rate_hz > 0:
        raise ValueError(f"rate_hz must be positive, got {rate_hz!r}")


def _generate(n_repetitions: int, seed: int, rate_hz: float) -> dict:
    check_repetitions(n_repetitions, rate_hz)
    rng = np.random.default_rng(seed)
    return {
        a: [_repetition(rng, a, rate_hz) for _ in range(int(n_repetitions))]
        for a in ACTIONS
    }


#: Irrelevant features of ``synthetic_actions(..., irrelevant=k)``: distractor k's
#: position [mm], a second object someone else moves about the desk meanwhile.
DISTRACTOR_AMPLITUDE_MM = 300.0


def distractor_names(k: int) -> tuple[str, ...]:
    """The names of ``k`` irrelevant features (with their unit)."""
    return tuple(f"distractor_{i + 1} [mm]" for i in range(int(k)))


def _distractors(rng: np.random.Generator, times: np.ndarray, k: int) -> np.ndarray:
    """(T, k) smooth positions unrelated to the action: per column an offset and
    three sinusoids of random frequency (0.1-0.6 Hz) and phase."""
    cols = []
    for _ in range(k):
        f = rng.uniform(0.1, 0.6, 3)
        phase = rng.uniform(0.0, 2 * np.pi, 3)
        amp = rng.uniform(0.3, 1.0, 3) * DISTRACTOR_AMPLITUDE_MM / 3
        wave = (amp * np.sin(2 * np.pi * f * times[:, None] + phase)).sum(axis=1)
        cols.append(rng.uniform(-1, 1) * DISTRACTOR_AMPLITUDE_MM + wave)
    return np.stack(cols, axis=1)


def synthetic_actions(
    n_repetitions: int = 7, seed: int = 0, *, rate_hz: float = 30.0,
    features: str = "marker", irrelevant: int = 0,
) -> dict[str, list[Demonstration]]:
    """Seeded demonstrations of MOVE, ROTATE, CLEAN and PAINT (paper section 4.1-4.2).

    Args:
        n_repetitions: repetitions per action (the paper recorded 7: 6 to
            generalize, 1 to test).
        seed: seed of the host random generator; equal seeds give equal data.
        rate_hz: sampling rate of the tracker (Kinect: 30 Hz).
        features: ``"marker"`` for the object features (X, Y, Z [mm], area [px],
            hue, saturation, value, angle [deg]; F = 8) or ``"arm"`` for the
            demonstrator's hand tip, wrist, elbow and shoulder X, Y, Z [m] (F = 12).
            Both views of one seed describe the same repetitions.
        irrelevant: adds this many irrelevant features after those,
            ``"distractor_k [mm]"`` (`distractor_names`): the position of a second
            object moved about by someone else, unrelated to the action (an
            offset up to +-300 mm and slow waves of about that size, drawn anew
            for every repetition from a generator of its own, so the other
            features are those of ``irrelevant=0``).

    Returns:
        ``{action: [Demonstration, ...]}`` in the order MOVE, ROTATE, CLEAN, PAINT;
        demonstration ``k`` of action ``A`` is named ``"A-k"`` (k from 1), with
        times (T_k,) in seconds and features (T_k, F).

    Examples:
        >>> demos = synthetic_actions(n_repetitions=3, seed=1)
        >>> sorted(demos), demos["MOVE"][0].features.shape[1]
        (['CLEAN', 'MOVE', 'PAINT', 'ROTATE'], 8)
    """
    if features not in ("marker", "arm"):
        raise ValueError(f"features must be 'marker' or 'arm', got {features!r}")
    if isinstance(irrelevant, bool) or int(irrelevant) != irrelevant or irrelevant < 0:
        raise ValueError(f"irrelevant must be a whole number >= 0, got {irrelevant!r}")
    names = (MARKER_FEATURES if features == "marker" else ARM_FEATURES
             ) + distractor_names(irrelevant)
    reps = _generate(n_repetitions, seed, rate_hz)
    noise = np.random.default_rng([int(seed), 44])  # its own stream

    def values(r: _Repetition) -> np.ndarray:
        own = r.marker if features == "marker" else r.arm
        if not irrelevant:
            return own
        return np.concatenate([own, _distractors(noise, r.times, irrelevant)], 1)

    return {
        a: [
            Demonstration(
                times=r.times,
                features=values(r),
                feature_names=names,
                name=f"{a}-{k + 1}",
            )
            for k, r in enumerate(reps[a])
        ]
        for a in ACTIONS
    }


def synthetic_arm_actions(
    n_repetitions: int = 7, seed: int = 0, *, rate_hz: float = 30.0
) -> dict[str, list[Demonstration]]:
    """The demonstrator's arm points (F = 12) for the same repetitions (paper 4.2).

    Shorthand for ``synthetic_actions(n_repetitions, seed, features="arm")``.
    """
    return synthetic_actions(n_repetitions, seed, rate_hz=rate_hz, features="arm")


class SyntheticSequence(NamedTuple):
    """A recording of several actions in a row and where each one is."""

    recording: Demonstration  # marker features (F = 8), times in seconds from 0
    truth: list[tuple[str, float, float]]  # (action, start, end) of each motion, s


def synthetic_sequence(
    actions: Sequence[str] | None = None,
    seed: int = 0,
    *,
    pause_s: tuple[float, float] = (0.0, 0.0),
    rate_hz: float = 30.0,
) -> SyntheticSequence:
    """One recording in which several actions follow each other (marker features).

    Each action is a fresh repetition as `synthetic_actions` draws them (its own
    duration, hesitation, noise), cut to its motion and moved to start where the
    previous one left the marker (position, angle, colour, area). Between two
    actions, and before the first and after the last, the marker rests (tracking
    noise only) for a time drawn from ``pause_s``; ``(0, 0)`` puts the motions
    back to back.

    Args:
        actions: the action names in order (of `ACTIONS`, repeats allowed); default
            2 to 6 actions drawn at random.
        seed: host random seed.
        pause_s: (shortest, longest) rest in seconds, drawn uniformly per pause.
        rate_hz: sampling rate.

    Returns:
        The recording (named ``"sequence"``) and the true ``(action, start, end)``
        of each motion in seconds.

    Examples:
        >>> seq = synthetic_sequence(["MOVE", "CLEAN"], seed=1, pause_s=(0.5, 1.0))
        >>> [a for a, _, _ in seq.truth], seq.recording.n_features
        (['MOVE', 'CLEAN'], 8)
    """
    if not rate_hz > 0:
        raise ValueError(f"rate_hz must be positive, got {rate_hz!r}")
    lo, hi = pause_s
    if not 0.0 <= lo <= hi:
        raise ValueError(f"pause_s must be (shortest, longest) with 0 <= shortest "
                         f"<= longest, got {pause_s!r}")
    rng = np.random.default_rng(seed)
    if actions is None:
        actions = [str(a) for a in rng.choice(ACTIONS, size=rng.integers(2, 7))]
    actions = list(actions)
    unknown = [a for a in actions if a not in ACTIONS]
    if not actions or unknown:
        raise ValueError(f"actions must name some of {ACTIONS}, got {actions!r}")

    def rest(here: np.ndarray) -> np.ndarray:
        n = int(round(rng.uniform(lo, hi) * rate_hz))
        return here + rng.normal(0.0, _MARKER_NOISE, size=(n, here.shape[0]))

    here = None
    pieces, truth, count = [], [], 0
    for k, a in enumerate(actions):
        r = _repetition(rng, a, rate_hz)
        moving = np.flatnonzero((r.progress > 0.0) & (r.progress < 1.0))
        first, last = max(moving[0] - 1, 0), min(moving[-1] + 1, len(r.progress) - 1)
        start_value = r.marker[:first + 1].mean(axis=0)  # at rest before the motion
        end_value = r.marker[last:].mean(axis=0)  # and after it
        here = start_value if here is None else here
        if k == 0 or hi > 0:
            pieces.append(rest(here))
            count += len(pieces[-1])
        pieces.append(r.marker[first:last + 1] - start_value + here)
        truth.append((a, count / rate_hz, (count + last - first) / rate_hz))
        count += last - first + 1
        here = here + end_value - start_value
    pieces.append(rest(here))
    marker = np.concatenate(pieces)
    recording = Demonstration(np.arange(len(marker)) / rate_hz, marker,
                              MARKER_FEATURES, "sequence")
    return SyntheticSequence(recording, truth)


def select_features(
    demos: list[Demonstration], names: tuple[str, ...] | list[str]
) -> list[Demonstration]:
    """The same demonstrations restricted to the named feature columns, in that order.

    Raises:
        KeyError: a name is not a feature of the demonstration (both named).
    """
    out = []
    for d in demos:
        missing = [n for n in names if n not in d.feature_names]
        if missing:
            raise KeyError(
                f"demonstration {d.name!r} has no feature(s) {missing}; "
                f"it has {list(d.feature_names)}"
            )
        cols = [d.feature_names.index(n) for n in names]
        out.append(
            Demonstration(
                times=d.times, features=d.features[:, cols],
                feature_names=tuple(names), name=d.name,
            )
        )
    return out


# The clean execution goal: right-arm workspace of TEO, waist frame (x forward,
# y left, z up). A vertical circle in the plane x = 0.55 m in front of the right
# shoulder (0, -0.347, 0.498). Checked with the TEO model and the paper's three
# joints (shoulder flexion, abduction, elbow; forearm rotation 45 deg): every point
# of the circle is within 8 mm of a sampled reachable marker position (the spacing
# of 400k uniform samples of the joint box).
CLEAN_CENTRE_M: tuple[float, float, float] = (0.55, -0.45, 0.35)


def clean_circle_demos(
    centre: tuple[float, float, float] | np.ndarray = CLEAN_CENTRE_M,
    diameter: float = 0.30,
    n: int = 6,
    seed: int = 0,
    *,
    rate_hz: float = 30.0,
    duration_s: float = 7.4,
    noise_m: float = 0.003,
) -> list[Demonstration]:
    """Demonstrations of one revolution of a circle, as marker X, Y, Z [m].

    The circle lies in the vertical plane x = centre[0] (facing the robot), starts at
    its top and turns once. Each repetition has its own duration (about
    ``duration_s``), pauses, hesitation, a few millimetres of noise and a small
    offset of the whole circle, like a person's.

    Args:
        centre: circle centre (3,) in metres, in the robot's waist frame.
        diameter: circle diameter in metres (paper: 0.30).
        n: number of demonstrations (the paper generalized 6).
        seed: host random seed.
        rate_hz: sampling rate.
        duration_s: mean duration of the circling motion, seconds; with the
            paper's 1 s interval it sets the number of goal points. Each
            repetition adds about 1.6 s of pauses, so the default 7.4 s gives a
            mean duration of about 9 s: the paper's 9-point clean goal.
        noise_m: standard deviation of the tracking noise, metres.

    Returns:
        ``n`` Demonstrations named ``"clean-k"`` with features (T_k, 3) named X, Y, Z.
    """
    centre = np.asarray(centre, dtype=float)
    if centre.shape != (3,):
        raise ValueError(f"centre must have shape (3,), got {centre.shape}")
    if not diameter > 0:
        raise ValueError(f"diameter must be positive, got {diameter!r}")
    check_repetitions(n, rate_hz)
    rng = np.random.default_rng(seed)
    demos = []
    for k in range(int(n)):
        duration = duration_s * rng.uniform(0.85, 1.15)
        count = int(round((duration + 1.6) * rate_hz))
        p, _ = repetition_progress(rng, count, rate_hz, duration)
        theta = np.pi / 2.0 + 2.0 * np.pi * p  # start at the top, one revolution
        offset = centre + rng.normal(0.0, 0.004, 3)
        r = diameter / 2.0
        xyz = np.column_stack(
            [np.full(count, offset[0]), offset[1] + r * np.cos(theta),
             offset[2] + r * np.sin(theta)]
        )
        xyz = xyz + rng.normal(0.0, noise_m, size=xyz.shape)
        demos.append(
            Demonstration(
                times=np.arange(count) / rate_hz, features=xyz,
                feature_names=SPATIAL_FEATURES, name=f"clean-{k + 1}",
            )
        )
    return demos


def paint_ramp(n_points: int = 17) -> np.ndarray:
    """The paper's synthetic paint goal: painted percent rising 0 -> 100 (n_points, 1).

    With 17 points each step paints one of the 16 squares (6.25 %).
    """
    if int(n_points) != n_points or n_points < 2:
        raise ValueError(f"n_points must be an integer >= 2, got {n_points!r}")
    return np.linspace(0.0, 100.0, int(n_points))[:, None]
