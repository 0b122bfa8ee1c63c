"""The sections of an experiment config (``[data]``, ``[robot]``, ``[strategy]``,
...): one typed dataclass each, with its defaults and what each key means.
`cgda_jax.experiment.config.ExperimentConfig` holds one of each."""

from __future__ import annotations

import dataclasses
from typing import Any

__all__ = ["ControlConfig", "DataConfig", "FeasibilityConfig", "OutputConfig", "RealityConfig", "RecognitionConfig", "RobotConfig", "SceneConfig", "SelectionConfig", "StrategyConfig", "WorldConfig"]


@dataclasses.dataclass
class DataConfig:
    """Where the demonstrations (or the goal) come from.

    Attributes:
        source: "synthetic" (MOVE/ROTATE/CLEAN/PAINT, recognition), "clean_circle"
            (circle demos -> clean goal), "paint_ramp" (0 -> 100 % in
            ``goal_points`` steps), "xgnitive" (real TEO demonstrations),
            "move_box" (a box pushed along a table: x, y, yaw) or "rotate_valve"
            (a valve's angle); for the last two the goal keeps the demonstration
            columns the ``objects`` scene reads (`cgda_jax.datasets.objects`);
            "video" (recognition from a camera: ``data_dir`` holds one folder per
            action, each with that action's recordings in name order, tracked
            with `cgda_jax.vision` as ``cgda track`` does; execution: ``data_dir``
            holds the recordings of the one action to execute); "csv"
            (execution: every ``.csv`` file of ``data_dir``, as `load_csv` and
            ``cgda track --out`` write them, keeping ``columns``).
        features: synthetic: "marker" (8 object features), "spatial" (X, Y, Z) or
            "arm" (12 arm-point coordinates); video: "marker" (X_m, Y_m, Z_m,
            area_px, hue, saturation, value, angle_deg; needs depth), "spatial"
            (X_m, Y_m, Z_m) or "image" (the features without depth).
        color: video: the object's colour range (``"HLO-HHI,SMIN,VMIN"``) or "auto".
        n_repetitions, n_train: synthetic: repetitions per action; the first
            ``n_train`` generalize, the rest are test queries (video and xgnitive
            recognition: ``n_train`` likewise, of the recordings there are;
            ``recognition.split = "leave_one_out"`` uses every one in turn).
        seed: seed of the synthetic demonstrations.
        interval_s, method: generalization interval (s) and method ("paper" |
            "xgnitive").
        centre, diameter, n_demos: clean circle (metres, waist frame).
        goal_points: paint ramp length.
        data_dir: xgnitive data folder (default: $CGDA_XGNITIVE_DIR); video: the
            folder of action folders (recognition) or of recordings (execution);
            csv: the folder of CSV files.
        action, stream, columns: xgnitive action ("paint" | "iron"), stream and
            feature columns (see ``cgda_jax.data.XGNITIVE_COLUMNS``; a recognition
            run reads ``stream`` and ``columns`` of both actions, paint and iron,
            and no ``action``); csv: the feature columns to keep, in order (e.g.
            ``["X_m", "Y_m", "Z_m"]``).
        force_columns: xgnitive: wrist force/torque (jr3) columns put after
            ``columns`` (e.g. ``["Fz"]``; `cgda_jax.data.load_xgnitive_force`,
            each stream generalized on its own clock); empty: none.
        scale: factor applied to the goal's features (e.g. unit changes).
        start, end: move_box: the box's (x, y) before and after the push [m];
            rotate_valve: the valve angle before and after [rad] (one value);
            empty = the dataset's defaults.
        curve: move_box: sideways bulge of the path at its middle [m].
        object: move_box / rotate_valve: the object's name in the feature names
            ("" = "box" / "valve").
        duration_s: move_box / rotate_valve: mean duration of the motion [s]
            (0 = the dataset's 7.4 s; with the pauses and ``interval_s = 1``,
            about 9 goal points).
        irrelevant: synthetic: this many irrelevant features added
            (``distractor_k [mm]``, `cgda_jax.datasets.synthetic_actions`).
    """

    source: str = "synthetic"
    features: str = "marker"
    n_repetitions: int = 7
    n_train: int = 6
    seed: int = 0
    interval_s: float = 1.0
    method: str = "paper"
    centre: list[float] = dataclasses.field(default_factory=lambda: [0.55, -0.45, 0.35])
    diameter: float = 0.30
    n_demos: int = 6
    goal_points: int = 17
    data_dir: str = ""
    action: str = "paint"
    stream: str = "paintSquaresOnScreen"
    columns: list[str] = dataclasses.field(default_factory=lambda: ["percent"])
    force_columns: list[str] = dataclasses.field(default_factory=list)
    scale: float = 1.0
    start: list[float] = dataclasses.field(default_factory=list)
    end: list[float] = dataclasses.field(default_factory=list)
    curve: float = 0.0
    object: str = ""
    duration_s: float = 0.0
    color: str = "auto"
    irrelevant: int = 0


@dataclasses.dataclass
class RecognitionConfig:
    """Recognition: metric ("dtw" | "dtw_multi" | "euclidean"), query form, samples.

    ``query = "reduced"`` compares the test repetition after the same interval
    averaging as the generalized actions (the paper's "reduced test actions");
    ``"raw"`` compares the raw test samples.

    ``split``: which repetitions are test queries.  ``"first"``: the first
    ``data.n_train`` of each action generalize it, the rest are queries (the
    paper's split); ``"leave_one_out"``: every repetition in turn is the query and
    its action is generalized from all its other repetitions (the other actions
    from all theirs): for few recordings, as the real TEO ones (4 an action).
    """

    metric: str = "dtw"
    query: str = "reduced"
    n_samples: int = 100
    split: str = "first"


@dataclasses.dataclass
class SelectionConfig:
    """``[selection]``: the CGDA authors' selection (`cgda_jax.select`), applied
    to each action's demonstrations before generalization.

    ``demonstrations``: drop the outlier demonstrations
    (`cgda_jax.select_demonstrations`; recognition: of the training ones).
    ``features`` (recognition only): keep the features that
    `cgda_jax.select_features` keeps for at least one action (the library needs
    one feature set; a feature every action discards is dropped), in the
    generalized actions and the test queries; demonstrations first.
    ``normalization``: "none", "minmax", "standardized" or "whole-experiment"
    (`cgda_jax.select.NORMALIZATIONS`); ``alpha``: the z-score above which a
    feature or demonstration is discarded (the authors' 0.5).
    """

    features: bool = False
    demonstrations: bool = False
    normalization: str = "none"
    alpha: float = 0.5


@dataclasses.dataclass
class ControlConfig:
    """``[robot.control]``: how dynamic mode drives the joints
    (`cgda_jax.sim.control`).

    ``mode``: "auto" (position actuators as the model has them; motors and other
    actuators through a joint-space PD) or "pd" (every driven joint through the PD,
    adding one where a joint has no actuator).  ``kp`` [N m/rad], ``kd``
    [N m s/rad], ``force_limit`` [N m]: the PD's, each one number for every PD joint
    or a table by joint name (empty: from the model; ``kp`` defaults to the force
    limit / 0.1 rad, ``kd`` to ``damping_ratio`` x critical damping).
    ``gravity``: the PD compensates gravity (MuJoCo's ``qfrc_bias`` at rest).
    """

    mode: str = "auto"
    kp: Any = dataclasses.field(default_factory=dict)
    kd: Any = dataclasses.field(default_factory=dict)
    force_limit: Any = dataclasses.field(default_factory=dict)
    damping_ratio: float = 1.0
    gravity: bool = True


@dataclasses.dataclass
class RobotConfig:
    """The robot: MJCF model (built-in name or path), evolved joints, marker.

    ``model``: a built-in model's name (``teo.xml``) or a file; a relative path in a
    config file is relative to that file's folder (one given with ``--set``, to the
    working folder).  ``marker_site``: the site whose position the scenes read;
    ``marker``: instead of it, ``{ body = "hand", pos = [x, y, z] }`` (a point fixed
    on a body, metres in its frame) or ``{ site = "..." }``.
    ``fixed`` holds joint values in DEGREES (converted to radians for the robot;
    default none: joints neither evolved nor fixed stay at the start posture, welded
    in dynamic mode).
    ``start``: start values of evolved joints in DEGREES (every execution starts
    there; default the model's ``qpos0`` or the keyframe's).
    ``keyframe``: a ``<key>`` of the model whose qpos is the start posture ("" = the
    model's qpos0).  Dynamic mode (``mode = "dynamic"``): ``physics`` "auto" | "mjx"
    | "mujoco"; ``waypoint_s`` seconds per waypoint (0 = the demonstrations' timing,
    mean duration / goal points; 1 s without demonstrations); ``timestep`` physics
    step in seconds (0 = the model's own); ``reduce`` welds unmoved joints.
    Both modes: ``waypoint_s`` and ``move_fraction`` (the share of a waypoint spent
    moving, minimum jerk; the rest holds) time the moves that the feasibility check
    judges.  ``limits``: joint limits that override the model's
    (`cgda_jax.sim.limits.read_limits`): ``velocity`` [rad/s], ``acceleration``
    [rad/s^2], ``effort`` [N m], each a number for every evolved joint or a table
    by joint name (``limits = { velocity = 2.0, effort = { r_elbow = 20.0 } }``).
    ``control``: ``[robot.control]`` (`ControlConfig`).
    """

    model: str = "teo.xml"
    joints: list[str] = dataclasses.field(
        default_factory=lambda: ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"]
    )
    marker_site: str = "marker"
    marker: dict[str, Any] = dataclasses.field(default_factory=dict)
    fixed: dict[str, float] = dataclasses.field(default_factory=dict)
    start: dict[str, float] = dataclasses.field(default_factory=dict)
    mode: str = "kinematic"
    substeps: int = 8
    keyframe: str = ""
    physics: str = "auto"
    waypoint_s: float = 0.0
    timestep: float = 0.0
    move_fraction: float = 0.6
    reduce: bool = True
    limits: dict[str, Any] = dataclasses.field(default_factory=dict)
    control: ControlConfig = dataclasses.field(default_factory=ControlConfig)


@dataclasses.dataclass
class WorldConfig:
    """Objects in the robot's world (`cgda_jax.sim.world.compose_world`).

    ``objects``: object dicts (``[[world.objects]]`` tables: ``piece``, ``pos``,
    optional ``name``, ``euler`` [deg] / ``quat`` and the piece's parameters, e.g.
    ``size``, ``mass``, ``friction``, ``radius``, ``damping``); with any, the robot is
    built with `Robot.from_world`.  ``contact_geoms``: robot geoms that touch the
    objects (e.g. ``["r_hand", "r_tool"]``).
    """

    objects: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    contact_geoms: list[str] = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class SceneConfig:
    """The scene: "marker" (features X, Y, Z), "paint" (painted %, a 4 x 4 wall) or
    "objects" (features of the simulated world, `cgda_jax.sim.ObjectScene`).

    ``params`` go to the scene: for "paint", keyword arguments of
    ``PaintWall.grid`` (x, ys, zs, root_height, radius, size).
    ``features`` ("objects"): ``[[scene.features]]`` entries such as
    ``{body = "box", quantity = "xy"}`` or ``{joint = "valve", quantity = "angle"}``
    (`cgda_jax.sim.features.FeatureSpec`).
    ``goal_path`` ("objects"): draw the goal as green spheres in the render: for a
    body's x/y features at the height ``goal_path_z`` [m] (e.g. a table's surface);
    for a hinge joint's angle at the site ``goal_path_site`` (e.g. "valve/rim") with
    the joint turned to each goal angle.
    """

    kind: str = "marker"
    params: dict[str, Any] = dataclasses.field(default_factory=dict)
    features: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    goal_path: bool = False
    goal_path_z: float = 0.0
    goal_path_site: str = ""


@dataclasses.dataclass
class StrategyConfig:
    """The execution strategy and its evolutionary algorithm (evosax name).

    ``options`` are extra keyword arguments of the strategy function (e.g.
    ``stagnation`` for FTE).  ``feasibility`` (default on): a run succeeds only
    with a motion the robot could perform (no penetration, joint limits kept, the
    approach included; see ``[feasibility]``); false: the paper's unconstrained
    execution.
    """

    name: str = "ie"
    algorithm: str = "CMA_ES"
    population_size: int = 16
    tolerance: float = 0.02
    max_generations: int = 100
    seed: int = 0
    chunk_size: int = 10
    options: dict[str, Any] = dataclasses.field(default_factory=dict)
    feasibility: bool = True


@dataclasses.dataclass
class FeasibilityConfig:
    """What a feasible motion is (`cgda_jax.sim.feasibility`; with
    ``strategy.feasibility`` on).

    ``penetration`` [m]: the deepest contact tolerated between the robot and
    itself or the world; ``penalty``: fitness added to an infeasible candidate
    (times 1 + its violation); ``collisions``: check collisions (false: limits
    only); ``self_collision``: the robot's own pairs too; ``exclude``: geom names
    left out of the check; ``samples``: collision samples per move; ``margin``
    [m]: how far the sampled distances must stay above the penetration limit, for
    what passes between samples; ``certify``: bound the distance between samples
    instead (a guarantee, far stricter on long moves near obstacles);
    ``max_step_deg``: the largest change of a joint between two waypoints (a larger
    one is flailing; the approach from the start posture excepted); ``geometry``:
    "round" (the robot's moving geoms as capsules that hold them: closed-form
    pairs, never more lenient) or "exact" (the geoms themselves).
    Dynamic mode, what the physics executed (`Feasibility.executed`):
    ``tracking_deg`` [deg; a slide: mm]: the largest error of an evolved joint
    from its commanded posture at any physics step; ``saturation``: the largest
    share of a move's physics steps with an evolved joint at its force limit.
    """

    penetration: float = 0.005
    penalty: float = 1000.0
    collisions: bool = True
    self_collision: bool = True
    exclude: list[str] = dataclasses.field(default_factory=list)
    samples: int = 10
    margin: float = 0.002
    certify: bool = False
    max_step_deg: float = 90.0
    tracking_deg: float = 30.0
    saturation: float = 0.75
    geometry: str = "round"


@dataclasses.dataclass
class OutputConfig:
    """Results: ``dir`` (parent folder), ``plots`` on/off, ``render`` on/off.

    ``render`` (execution runs): an animated GIF of the robot executing the best
    trajectory and a strip of frames (paper Fig. 8/11), rendered offscreen by
    MuJoCo (``MUJOCO_GL=egl`` or ``osmesa``). Without a working offscreen OpenGL
    the run goes on and one warning says why nothing was rendered.
    """

    dir: str = "results"
    plots: bool = True
    render: bool = True
    #: the video's free camera, over a default that frames the goal and the arm:
    #: ``lookat`` [x, y, z] m, ``distance`` m, ``azimuth``, ``elevation`` deg
    #: (`cgda_jax.experiment.rules.check_camera`)
    camera: dict[str, Any] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass
class RealityConfig:
    """A mismatched world the result is also executed on (`cgda_jax.reality.mismatch`,
    dynamic mode only), when ``enabled`` (``cgda run CONFIG --reality``).

    Each perturbation is a number or a ``[low, high]`` range drawn with ``seed``:
    ``mass_scale`` (object bodies' masses; every body without objects),
    ``friction_scale`` (sliding friction), ``joint_offset_deg`` (per evolved joint),
    ``damping_scale`` (the evolved joints'), ``gain_scale`` (actuator kp),
    ``noise`` (feature noise, standard deviation in feature units), ``delay_s``
    (feature latency), ``marker_noise`` (the tool's measured position, m).

    How strategy ``oet`` closes its loop on that world
    (`cgda_jax.strategies.closed_loop.run_oet_closed_loop`): ``step_tolerance``
    (a step's evolution in the model stops below this error; 0: the strategy's
    tolerance; the world's measurement is judged at the strategy's tolerance),
    ``relocate_objects`` (the model's objects put where the world measured them
    after each step), ``correct`` (the next target moved against the last
    measured offset from the model's prediction), ``calibrate`` (the joints'
    offsets estimated from the measured tool, `cgda_jax.reality.calibrate`).
    """

    enabled: bool = False
    seed: int = 0
    mass_scale: Any = 1.0
    friction_scale: Any = 1.0
    joint_offset_deg: Any = 0.0
    damping_scale: Any = 1.0
    gain_scale: Any = 1.0
    noise: Any = 0.0
    delay_s: Any = 0.0
    marker_noise: Any = 0.0
    step_tolerance: float = 0.0
    relocate_objects: bool = True
    correct: bool = True
    calibrate: bool = True

    def mismatch_table(self) -> dict[str, Any]:
        """The `cgda_jax.reality.mismatch.Mismatch` keys and values."""
        return {k: v for k, v in dataclasses.asdict(self).items()
                if k not in ("enabled", *LOOP_KEYS)}

    def loop_options(self) -> dict[str, Any]:
        """The closed loop's keyword arguments of `run_oet_closed_loop`."""
        return {"step_tolerance": self.step_tolerance or None,
                "relocate_objects": self.relocate_objects, "correct": self.correct,
                "calibrate": self.calibrate}


#: The `RealityConfig` keys that set the closed loop, not the world.
LOOP_KEYS = ("step_tolerance", "relocate_objects", "correct", "calibrate")
