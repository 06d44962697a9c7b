"""Settings of the dynamic tether filter (typed, validated like every config section).

The shared time-alignment, gate and rangefinder-validity settings stay in
:class:`~tether_companion.estimation.config.EstimatorConfig`; this section holds what only
the dynamic filter has: its noise densities, the cable's weight, the rotor-drag coefficient,
the anchor's height above the ground, the initialisation window and the publication bounds
behind its observability status. :func:`drag_per_s` resolves the rotor-drag coefficient from
this section or, when unset, the vehicle profile.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from tether_companion.config import load_yaml, spec
from tether_companion.physics.vehicle import VehicleProfile

FORCE_BALANCE = "force_balance"
"""Formulation (a): the force balance drives the prediction, the accelerometer is measured."""
INERTIAL = "inertial"
"""Formulation (b): the accelerometer drives the prediction, the force balance is measured."""


@dataclass(frozen=True)
class DynamicNoise:
    """Process noise spectral densities (random walks and unmodelled forces)."""

    acceleration_m2ps3: float = spec(
        1e-4,
        exclusive_minimum=0.0,
        doc="force_balance: unmodelled forces per unit mass (gusts, motor lag, model error)"
        " driving the velocity [m^2/s^3]",
    )
    force_residual_m2ps3: float = spec(
        0.02,
        exclusive_minimum=0.0,
        doc="inertial: what the force-balance measurement does not model (gusts through"
        " drag, quadratic body drag, vibration, motor lag), time-correlated, as the white"
        " density of the same information: a force error of std sigma [m/s^2] correlated"
        " over tau [s] counts 2 sigma^2 tau [m^2/s^3]",
    )
    position_m2ps: float = spec(1e-6, exclusive_minimum=0.0, doc="position [m^2/s]")
    tension_n2ps: float = spec(2.0, exclusive_minimum=0.0, doc="chord tension [N^2/s]")
    winch_tension_n2ps: float = spec(
        0.1,
        exclusive_minimum=0.0,
        doc="chord tension while a constant-tension winch's tension is fused: what its control"
        " lets through and the chord tension's change with the geometry at a held anchor"
        " tension [N^2/s]",
    )
    thrust_scale_per_s: float = spec(
        1e-5, exclusive_minimum=0.0, doc="thrust scale factor (battery sag) [1/s]"
    )
    accel_bias_m2ps5: float = spec(
        1e-4,
        exclusive_minimum=0.0,
        doc="accelerometer bias random walk, also carrying the flight controller's slowly"
        " wandering attitude error (g times its angle, 2 sigma^2 / tau) [(m/s^2)^2/s]",
    )
    wind_std_mps: float = spec(
        3.0,
        exclusive_minimum=0.0,
        doc="the wind, north and east, as a first-order Gauss-Markov process about calm: its"
        " stationary standard deviation (a light-turbulence day's mean wind and gusts at a few"
        " metres) [m/s]",
    )
    wind_correlation_s: float = spec(
        15.0,
        exclusive_minimum=0.0,
        doc="that process's correlation time: the wind reverts toward calm as exp(-t/tau)"
        " and its white driving noise is 2 wind_std_mps^2 / tau (1.2 m^2/s^3 at 3 m/s, 15 s;"
        " light Dryden gusts at a few metres, 1.5 m/s over ~5 s, drive 0.9 m^2/s^3). 15 s and"
        " 3 m/s chosen on tuning seeds of the gusty hover (docs/estimation-history.md,"
        " gust25) [s]",
    )


@dataclass(frozen=True)
class DynamicInitial:
    """Prior uncertainty of the states the first second of data does not measure."""

    velocity_std_mps: float = spec(0.5, exclusive_minimum=0.0, doc="velocity [m/s]")
    thrust_scale: float = spec(
        1.0, exclusive_minimum=0.0, doc="prior mean of the thrust scale factor [1]"
    )
    thrust_scale_std: float = spec(0.1, exclusive_minimum=0.0, doc="thrust scale factor [1]")
    thrust_scale_hypotheses: int = spec(
        5,
        minimum=1,
        maximum=15,
        doc="filters started side by side over +-1.5 std of the thrust scale (1: one filter)",
    )
    accel_bias_std_mps2: tuple[float, float, float] = spec(
        (0.2, 0.2, 0.2), exclusive_minimum=0.0, doc="accelerometer bias, body x y z [m/s^2]"
    )
    wind_std_mps: float = spec(2.0, exclusive_minimum=0.0, doc="wind, north and east [m/s]")
    wind_hypotheses: int = spec(
        4,
        minimum=0,
        maximum=12,
        doc="bearing hypotheses: members started beside the thrust-scale ones with the"
        " window's force less the drag of this many winds on a ring (the pull's direction,"
        " so the bearing, differs with the wind a steady hover cannot tell), kept while the"
        " data do not reject them; the pull rule relaxes once they are rejected (0: off) [1]",
    )
    wind_hypothesis_radius_std: float = spec(
        2.0, exclusive_minimum=0.0, doc="the ring's radius in wind prior standard deviations [1]"
    )
    window_s: float = spec(
        1.0, exclusive_minimum=0.0, doc="data averaged to initialise (tension direction) [s]"
    )
    thrust_scale_bank_max_s: float = spec(
        6.0,
        exclusive_minimum=0.0,
        doc="the hypotheses run side by side this long undecided, then those below 1 % weight"
        " go and those one Gaussian represents collapse to their moments (the cable's"
        " sphere linear over them, bank_reduction.py); members far apart run on until the"
        " data decide (6 s against 30 s, with imu_ticks_per_fusion 4: 4x cheaper over a 20 s"
        " flight; docs/estimation-history.md, the bank21 section) [s]",
    )


@dataclass(frozen=True)
class DynamicFilterConfig:
    """The dynamic tether filter (issue 10)."""

    formulation: str = spec(
        INERTIAL,
        choices=(FORCE_BALANCE, INERTIAL),
        doc="force_balance: dynamics predict, accelerometer measured; inertial: the reverse",
    )
    accel_noise_std_mps2: float = spec(
        0.15, exclusive_minimum=0.0, doc="accelerometer force-balance noise per axis [m/s^2]"
    )
    drag_per_s: float | None = spec(
        None,
        minimum=0.0,
        doc="rotor drag a = -mu v_air, body horizontal [1/s]; null: from the vehicle profile",
    )
    cable_weight_n_per_m: float = spec(
        0.0, minimum=0.0, doc="cable weight per length (0: a light, straight cable) [N/m]"
    )
    load_cell_noise_std_n: float = spec(0.1, exclusive_minimum=0.0, doc="load cell [N]")
    winch_length_noise_std_m: float = spec(
        0.05,
        exclusive_minimum=0.0,
        doc="winch length's reading noise: a drum encoder's 1 cm steps and its report's age"
        " (0.1 s at the 0.3-0.5 m/s a constant-tension winch reels in a gusty hover) [m]",
    )
    winch_latency_s: float = spec(
        0.1,
        minimum=0.0,
        maximum=2.0,
        doc="age of the winch's length at its time stamp (fused as the drone's distance that"
        " long before the stamp, p - latency v; 0 for a sensor that stamps when it measures) [s]",
    )
    cable_angle_latency_s: float = spec(
        0.05,
        minimum=0.0,
        maximum=2.0,
        doc="age of the ground station's cable angle at its time stamp (fused at the drone's"
        " position that long before the stamp; 0 for a sensor that stamps when it measures) [s]",
    )
    winch_length_offset_std_m: float = spec(
        0.1,
        minimum=0.0,
        maximum=10.0,
        doc="winch length's zero error (where the encoder count was zeroed): the prior of the"
        " filter's winch-offset state [m]",
    )
    winch_length_scale_std: float = spec(
        0.01,
        minimum=0.0,
        maximum=0.5,
        doc="winch length's scale error (the drum's effective radius: layering, wear): the"
        " prior of the filter's winch-scale state [1]",
    )
    slack_tension_n: float = spec(
        0.2, minimum=0.0, doc="below this tension the cable is reported slack [N]"
    )
    min_thrust_fraction: float = spec(
        0.5,
        minimum=0.0,
        maximum=1.0,
        doc="thrust below this fraction of the weight: on the ground, force balance not fused",
    )
    touchdown_height_m: float = spec(
        0.3,
        minimum=0.0,
        doc="estimated height of the centre of mass above the ground (the anchor's height "
        "above the ground minus the down position) below which the drone is touching down or "
        "just lifted off: position withheld (status on_ground), the ground's contact force "
        "being no part of the model and the rangefinder at its minimum range [m]",
    )
    learn_calibration: bool = spec(
        True,
        doc="let the ground station's calibration states (winch offset and scale, the angle's"
        " elevation zero; the azimuth zero never, the autopilot's heading error would be taken"
        " as it) learn once the filter has settled; off, they stay consider states (their"
        " spread kept in the covariance, never estimated): with calibration errors to learn"
        " it cut our error 2-5x on ArduPilot SITL and the simulator's down error 0.071 ->"
        " 0.044 m; where the sensors are exact it costs up to 0.03 m after the fly-out"
        " (docs/estimation.md)",
    )
    rest_velocity_std_mps: float = spec(
        0.05,
        exclusive_minimum=0.0,
        doc="velocity noise while the drone rests on the ground (motors idle or the autopilot"
        " says landed, the accelerometer reading g), fused as a zero-velocity update [m/s]",
    )
    rest_height_m: float = spec(
        0.1,
        minimum=0.0,
        maximum=2.0,
        doc="height of the centre of mass above the ground when landed (the landing gear) [m]",
    )
    rest_height_std_m: float = spec(
        0.1,
        exclusive_minimum=0.0,
        doc="uncertainty of rest_height_m [m] (with the terrain's, the height's at rest)",
    )
    max_horizontal_std_m: float = spec(
        0.5, exclusive_minimum=0.0, doc="horizontal std beyond which the pull is too weak [m]"
    )
    unmodelled_force_std_n: float = spec(
        0.2,
        minimum=0.0,
        doc="horizontal force on the drone the model leaves out and the filter cannot average"
        " away (gusts' and body drag correlated over seconds): the turn of the cable it"
        " causes, |p| sigma / T across the cable, is added to the published position"
        " covariance [N]",
    )
    bearing_position_walk_m2ps: float = spec(
        0.1,
        minimum=0.0,
        doc="the published position covariance is kept at least as wide across the cable as"
        " a small filter of the horizontal force's constant offsets allows (a steady hover"
        " does not tell the bearing from a cross wind; estimation/dynamic/consistency.py):"
        " the random walk of its position offset, how far the estimate's positions seconds"
        " apart may be off relative to each other; 0: off [m^2/s]",
    )
    bearing_wind_walk_m2ps3: float = spec(
        0.3,
        minimum=0.0,
        doc="that small filter's wind random walk: how fast the cross wind changes that a"
        " turn of the bearing must beat (the gusty hover's turbulence is 1.3 as a random walk;"
        " chosen on seeds 1-5 of the realistic scenarios) [m^2/s^3]",
    )
    unmodelled_force_correlation_s: float = spec(
        1.0,
        exclusive_minimum=0.0,
        doc="time over which the unmodelled horizontal force stays correlated: the bearing"
        " window counts one independent force sample of unmodelled_force_std_n per this"
        " time [s]",
    )
    min_pull_over_wind_drag: float = spec(
        4.0,
        minimum=0.0,
        doc="publish only while the horizontal pull exceeds this many times the rotor drag of"
        " a wind of initial.wind_std_mps or of the estimated wind, whichever is larger (the"
        " bearing is unknown below) [1]",
    )
    confirmed_pull_over_wind_drag: float = spec(
        2.0,
        minimum=0.0,
        doc="min_pull_over_wind_drag once every other bearing hypothesis of the bank"
        " (initial.wind_hypotheses) converged to the best member's (the data, not the start,"
        " chose the bearing), until the filter's cable goes slack (docs/estimation-history.md, the"
        " bearing hypotheses) [1]",
    )
    imu_ticks_per_fusion: int = spec(
        4,
        minimum=1,
        maximum=20,
        doc="inertial: the filter steps over this many IMU ticks at once (their specific"
        " forces summed, the state as tick by tick) and fuses the force balance then, its"
        " white noise scaled to that interval; the published estimate is stepped every tick"
        " (4 against 1: the same information, the force residual being correlated over ~1 s;"
        " with the 6 s bank 4x cheaper; docs/estimation-history.md, Cost per IMU tick) [1]",
    )
    noise: DynamicNoise = spec(default_factory=DynamicNoise, doc="process noise")
    initial: DynamicInitial = spec(default_factory=DynamicInitial, doc="initialisation")


def load_dynamic_config(path: str | Path) -> DynamicFilterConfig:
    """Load a :class:`DynamicFilterConfig` from YAML.

    Raises
    ------
    ConfigError
        When the file is missing or a key is unknown, mistyped or out of range.
    """
    return load_yaml(DynamicFilterConfig, path)


def drag_per_s(dynamic: DynamicFilterConfig, vehicle: VehicleProfile) -> float:
    """Rotor drag coefficient ``mu`` [1/s]: the config's, else the profile's
    ``rotor_drag_per_s`` when set (> 0), else its legacy isotropic linear drag coefficient over
    the mass."""
    if dynamic.drag_per_s is not None:
        return dynamic.drag_per_s
    if vehicle.rotor_drag_per_s > 0.0:
        return vehicle.rotor_drag_per_s
    return vehicle.drag_coefficient_n_s_per_m / vehicle.mass_kg
