"""Episodes of ``n`` vehicles advanced together: the body of both environments.

:class:`EnvBatch` holds the state of ``n`` episodes of one configuration
(:class:`~wall_env.config.EnvConfig`) and steps them with one call of the compiled
control step (:class:`~wall_env.dynamics.BatchSimulator`, closed-form contact
included). Observation, reward, termination and info are built with NumPy on all
rows at once. The single environment (:class:`~wall_env.env.WallInspectorEnv`) is the
batch of one; the vector environment (:class:`~wall_env.vector_env.WallInspectorVectorEnv`)
adds Gymnasium's autoreset around the same object. Random numbers come from per-row
streams (:mod:`wall_env.streams`), so row ``k`` seeded with ``s`` flies exactly as a
single env seeded with ``s``.

Flight conditions (:mod:`wall_env.conditions`) act on every row: the command reaches the
rotors through a delay line and the compiled step's per-row timing (latency in whole
physics steps, motor lag), the wind through the drag effects' parameters, and the
observation is built from the estimated state: the state the observation delay makes
stale, with the state-estimate error on top. The reward, the termination and ``info``
are of the true state. In ideal conditions none of this runs.

A scene with bodies (boxes, cylinders, meshes: :mod:`wall_env.bodies`) adds PyBullet's
queries (:mod:`wall_env.surfaces`) around the compiled step: at each reset and after each
step, every row's rotors get their local surfaces (written into the row's scene vector,
which the compiled step's suction reads over the next step), and a row that some probe
has near a surface gets a contact query; a contact is answered with the planes' response
(:func:`wall_env.contact.respond`). Observation and info then count the bodies as walls:
a rotor's clearance is its distance to the nearest plane or body surface.

Random draws of an episode, per row and in this order: at reset, one uniform per
randomised setting (:data:`~wall_env.config.RANDOMIZABLE` order, those configured; a push
takes one more for its direction) and nine for the start perturbation (position,
velocity, roll/pitch/yaw), then twelve normals for the sensing biases (with a sensing
error) and six for the turbulence's start (with turbulence); at each step, four normals for
the command noise (none without noise), six for the turbulence and 24 for the sensing
error (each only when configured).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wall_env.conditions import DelayLine, SensingErrors, TurbulenceState
from wall_env.conditions.latency import split_delay
from wall_env.config import DRAG_EFFECTS, EnvConfig
from wall_env.contact import SURFACES, respond
from wall_env.dynamics import STATE_SIZE, BatchSimulator, StateIndex, Timing
from wall_env.motor_lag import MIN_LAG_STEPS
from wall_env.observation import CLEARANCE_CAP, OBSERVATION_FIELDS, OBSERVATION_SIZE, PREVIEW_STEPS
from wall_env.rotations import euler_xyz_to_quat_rows, quat_to_rotation_rows
from wall_env.streams import RandomStreams
from wall_env.vehicle import GRAVITY

__all__ = ["EnvBatch", "check_actions", "info_row"]

_NO_SURFACE = np.array([None, *SURFACES], dtype=object)  # collision_surface by code: 0 = none
_ROW_MAJOR = np.array([0, 3, 6, 1, 4, 7, 2, 5, 8])  # entries of a column-major 3x3 in row-major order
#: m, the least clearance (wall, ground, ceiling) a perturbed start keeps: a start perturbation that would bring the
#: vehicle closer than this to a plane (or than its unperturbed start, if that is closer) is mirrored back out along
#: the plane's normal (:meth:`EnvBatch._keep_start_clear`), so that no episode starts touching or inside a surface
#: (WallHover's 5 cm position spread about a start 4.7 cm clear of the wall put 2.8 % of its starts inside it)
START_CLEARANCE = 0.01


def check_actions(actions: Any, n: int | None) -> np.ndarray:
    """Actions as a float64 array ``(n, 4)`` (``n=None``: one action ``(4,)``), or a ``ValueError``
    saying what is wrong. Values outside [-1, 1] are clipped later; NaN and infinity are refused."""
    shape = (4,) if n is None else (n, 4)
    array = np.asarray(actions)
    if array.dtype.kind not in "biuf":
        raise ValueError(f"action must be real numbers (thrust, wx, wy, wz in [-1, 1]) of shape {shape}, "
                         f"got dtype {array.dtype}")
    if array.shape != shape:
        raise ValueError(f"action must have shape {shape} (thrust, wx, wy, wz in [-1, 1]), got shape {array.shape}")
    array = array.astype(np.float64)
    finite = np.isfinite(array)
    if not finite.all():
        if n is None:
            raise ValueError(f"action must be finite, got {array.tolist()}")
        rows = np.flatnonzero(~finite.all(axis=1))
        listed = ", ".join(f"row {r}: {array[r].tolist()}" for r in rows[:3]) + (" ..." if len(rows) > 3 else "")
        raise ValueError(f"action must be finite; {len(rows)} of {n} rows are not ({listed})")
    return array


def info_row(info: dict[str, Any], k: int) -> dict[str, Any]:
    """Row ``k`` of a batch info from :meth:`EnvBatch.infos` (fresh arrays of ``n`` rows, nested
    dicts), with plain Python scalars; vectors are views of those fresh arrays."""
    out: dict[str, Any] = {}
    for key, value in info.items():
        if type(value) is dict:
            out[key] = info_row(value, k)
        elif value.ndim == 1:
            out[key] = value[k] if value.dtype == object else value[k].item()
        else:
            out[key] = value[k]
    return out


class EnvBatch:
    """``n`` episodes of ``config``; see the module docstring."""

    def __init__(self, config: EnvConfig, n: int):
        self.config = config
        self.n = n
        cfg = config
        geometry = cfg.geometry
        scene, reference = cfg.build()
        self.configured = (scene, reference)  # the configured scene and reference (each episode's may differ)
        self.simulator = BatchSimulator(cfg.vehicle, cfg.truth, scene.structure, cfg.control_dt,
                                        cfg.physics_substeps, n, lagged=cfg.lagged)
        self.streams = RandomStreams(n)
        sim = self.simulator
        sim.restitution[:] = cfg.restitution
        self._theta0 = cfg.truth.theta()
        sim.theta[:] = self._theta0
        sim.mass[:] = cfg.vehicle.mass
        sim.scene[:] = geometry.scene_vector
        self._suction_columns = cfg.suction_columns
        self._suction_index = cfg.truth.names.index("wall_suction") if "wall_suction" in cfg.truth.names else None
        self._effect_names = list(cfg.truth.names)
        self._yaw = float(reference.yaw)
        self._ref_p, self._ref_v = geometry.p_ref, geometry.v_ref
        # the observation's reference preview at every step, p_ref(t + k stride) - p_ref(t) (steps, 12):
        # one gather per observation instead of a gather and a subtraction
        preview = cfg.preview_stride * np.arange(1, PREVIEW_STEPS + 1)
        last = len(self._ref_p) - preview[-1]
        steps = np.arange(last)
        preview_table = (self._ref_p[steps[:, None] + preview] - self._ref_p[steps, None, :]).reshape(last, -1)
        # what an observation reads of the reference at step i, in one row: p_ref, v_ref, preview (18)
        self._ref_table = np.concatenate([self._ref_p[:last], self._ref_v[:last], preview_table], axis=1)
        self._rotors = cfg.vehicle.rotor_positions_array
        self._n_walls = len(scene.walls)
        planes = ["wall"] * self._n_walls + (["ground"] if cfg.base_scene.ground_z is not None else []) \
            + (["ceiling"] if cfg.base_scene.ceiling_z is not None else [])
        self._plane_codes = np.array([1 + SURFACES.index(p) for p in planes], dtype=np.int64)
        # a scene with bodies: PyBullet answers where the surfaces near each rotor are (wall_env.surfaces)
        self.surfaces: Any = None
        self._surface_columns = scene.surfaces_slice
        if scene.has_bodies:
            from wall_env.surfaces import SurfaceQuery

            self.surfaces = SurfaceQuery(scene, cfg.vehicle, cfg.surface_reach)
        self.surface_distance = np.full((n, 4), np.inf)  # each rotor's distance to its nearest body surface
        self.surface_normal = np.zeros((n, 4, 3))  # that surface's outward normal
        self.surface_contact = np.zeros(n, dtype=bool)  # a contact with a body in the latest step
        self._noise_std = cfg.noise_std
        self._mapping = cfg.action_mapping

        # episode state, one row per vehicle (the state vector itself is simulator.x)
        self.step_index = np.zeros(n, dtype=np.int64)
        self.previous_action = np.zeros((n, 4))
        self.collisions = np.zeros(n, dtype=np.int64)
        self.command = np.zeros((n, 4))
        self.surface = np.zeros(n, dtype=np.int64)  # 0: none, else 1 + index in SURFACES
        self.strayed = np.zeros(n, dtype=bool)
        self.forces = np.zeros_like(sim.forces)
        self.rotor_suction = np.zeros_like(sim.rotor_suction)  # column-major 3 x 4 per row
        self.R = np.zeros((n, 9))  # column-major per row, of the current state
        self.distances = np.zeros((n, 4 * self._n_walls))  # column-major (n_walls x 4) per row
        self.ref_offset = np.zeros((n, 3))
        self.episode_parameters = {key: np.zeros(n) for key in cfg.randomize}
        self._init_conditions()

    def _init_conditions(self) -> None:
        """The per-row state of the flight conditions (none of it in ideal conditions)."""
        cfg, n = self.config, self.n
        conditions = cfg.conditions
        substeps = cfg.physics_substeps
        self._hover_command = self._mapping.to_physical(np.zeros((1, 4)))
        # latency, in physics steps per row: the configured one, or drawn at reset
        command_steps, observation_steps = conditions.latency.physics_steps(cfg.physics_dt)
        self.command_delay = np.full(n, command_steps, dtype=np.int64)
        self.observation_delay = np.full(n, observation_steps, dtype=np.int64)
        longest = max(command_steps, observation_steps)
        if "latency" in cfg.randomize:
            longest = int(round(cfg.randomize["latency"][1] / cfg.physics_dt))
        depth = longest // substeps + 2
        self._commands = DelayLine(n, depth, 4) if longest else None
        self._observed = DelayLine(n, depth, STATE_SIZE) if longest else None
        self._set_delays(slice(None))
        self._sensing = (SensingErrors(conditions.sensing, n, cfg.control_dt)
                         if not conditions.sensing.is_zero else None)
        turbulence = conditions.wind.turbulence
        self._turbulence = TurbulenceState(turbulence, n, cfg.control_dt) if turbulence is not None else None
        self._mean_wind = np.asarray(conditions.wind.mean, dtype=float)
        self._wind_columns = [c for c in (cfg.parameter_columns(e, "w") for e in DRAG_EFFECTS) if c is not None]
        self._push_columns = cfg.parameter_columns("constant_force", "F") if "push" in cfg.randomize else None
        # the observation is of the true state unless a delay or an estimate error stands between them
        self.ideal_observation = self._observed is None and self._sensing is None
        self.x_estimate = self.simulator.x if self.ideal_observation else np.zeros((n, STATE_SIZE))
        self.R_estimate = self.R if self.ideal_observation else np.zeros((n, 9))
        self.distances_estimate = self.distances if self.ideal_observation else np.zeros((n, 4 * self._n_walls))
        self.surface_distance_estimate = self.surface_distance if self.ideal_observation else np.full((n, 4), np.inf)
        self.surface_normal_estimate = self.surface_normal if self.ideal_observation else np.zeros((n, 4, 3))

    def _set_delays(self, rows: np.ndarray | slice) -> None:
        """The compiled step's command switch and observation sample for the delays of ``rows``."""
        substeps = self.config.physics_substeps
        timing = self.simulator.timing
        timing[rows, Timing.command_switch] = split_delay(self.command_delay[rows], substeps)[1]
        timing[rows, Timing.observe_after] = substeps - split_delay(self.observation_delay[rows], substeps)[1]

    def _geometry(self, x: np.ndarray, scene: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``R_body_to_world`` (column-major, ``(k, 9)``) and rotor-wall distances (``(k, 4 n_walls)``,
        column-major ``n_walls x 4``) of states ``x`` ``(k, 17)`` in scenes ``(k, S)``."""
        k = x.shape[0]
        R = quat_to_rotation_rows(x[:, StateIndex.q_body_to_world])  # (k, 3, 3)
        distances = np.zeros((k, 4 * self._n_walls))
        if self._n_walls:
            rotors_world = x[:, StateIndex.p_world, None] + (R.reshape(3 * k, 3) @ self._rotors.T).reshape(k, 3, 4)
            walls = scene[:, : 6 * self._n_walls].reshape(k, self._n_walls, 2, 3)
            normals, points = walls[:, :, 1], walls[:, :, 0]
            # n . (r - c) for every wall and rotor, written out over the three axes (NumPy's batched
            # matmul of 1x3 by 3x4 matrices costs more than these six array operations)
            d = -(normals * points).sum(axis=2)[:, :, None]  # (k, walls, 4)
            for axis in range(3):
                d = d + normals[:, :, axis, None] * rotors_world[:, None, axis, :]
            distances = d.transpose(0, 2, 1).reshape(k, -1)
        return R.transpose(0, 2, 1).reshape(k, 9), distances

    def _estimate(self, rows: np.ndarray | slice, x_seen: np.ndarray) -> None:
        """The estimated state of ``rows`` from the state their observation shows (``x_seen``) and their
        current sensing error."""
        x_est = SensingErrors.apply(x_seen, self._sensing.error[rows]) if self._sensing is not None else x_seen
        self.x_estimate[rows] = x_est
        self.R_estimate[rows], self.distances_estimate[rows] = self._geometry(x_est, self.simulator.scene[rows])
        if self.surfaces is not None:  # what the estimate shows of the bodies: a query at the estimated pose
            found = self.surfaces.rotor_surfaces(x_est[:, StateIndex.p_world], x_est[:, StateIndex.q_body_to_world],
                                                 np.zeros((x_est.shape[0], self._surface_columns.stop
                                                           - self._surface_columns.start)))
            self.surface_distance_estimate[rows] = found.distance
            self.surface_normal_estimate[rows] = found.normal

    def _query_surfaces(self, rows: np.ndarray | slice) -> Any:
        """Each rotor's local surfaces of ``rows`` at their current state, into their scene vectors (what the
        compiled step's suction reads over the next step)."""
        sim = self.simulator
        x = sim.x[rows]
        block = sim.scene[rows, self._surface_columns]
        found = self.surfaces.rotor_surfaces(x[:, StateIndex.p_world], x[:, StateIndex.q_body_to_world], block)
        sim.scene[rows, self._surface_columns] = block
        self.surface_distance[rows] = found.distance
        self.surface_normal[rows] = found.normal
        return found

    def _body_contacts(self, found: Any) -> None:
        """Contacts with the bodies after a step: rows some probe has within reach of a surface are asked; the
        deepest contact is answered with the planes' response until the vehicle is clear (at most four times),
        and a row that moved gets its local surfaces again."""
        sim, query = self.simulator, self.surfaces
        self.surface_contact[:] = False
        near = np.minimum(found.distance.min(axis=1), found.centre_distance) < query.contact_reach
        for row in np.flatnonzero(near).tolist():
            x = sim.x[row]
            for _ in range(4):
                contacts = query.contacts(x[StateIndex.p_world], x[StateIndex.q_body_to_world])
                if not contacts:
                    break
                depth, normal = contacts[0]
                x[StateIndex.p_world], x[StateIndex.v_world] = respond(
                    x[StateIndex.p_world], x[StateIndex.v_world], normal, depth, sim.restitution[row, 0])
                self.surface_contact[row] = True
        moved = np.flatnonzero(self.surface_contact)
        if len(moved):
            self._query_surfaces(moved)
            self.R[moved], self.distances[moved] = self._geometry(sim.x[moved], sim.scene[moved])
            ends = moved[sim.timing[moved, Timing.observe_after] >= self.config.physics_substeps]
            sim.x_observed[ends] = sim.x[ends]  # an observation of the step's end sees the response

    def close(self) -> None:
        """Let go of the PyBullet client of the surface queries (a scene with bodies)."""
        if self.surfaces is not None:
            self.surfaces.close()

    # ------------------------------------------------------------------ reset
    def reset(self, rows: np.ndarray | slice, spread: np.ndarray | float = 1.0) -> None:
        """Start new episodes in ``rows`` (indices, or ``slice(None)`` for all; start perturbation
        scaled by ``spread``, 0 or 1)."""
        cfg, sim = self.config, self.simulator
        task = cfg.task
        ranges = cfg.randomize
        pushed = "push" in ranges
        u = self.streams.uniform(rows, len(ranges) + pushed + 9)
        k = u.shape[0]
        sample = {}
        for j, (key, (low, high)) in enumerate(ranges.items()):
            sample[key] = low + (high - low) * u[:, j]
            self.episode_parameters[key][rows] = sample[key]
        geometry = cfg.geometry
        if ranges:
            theta = np.broadcast_to(self._theta0, (k, self._theta0.size)).copy()
            for name, column in self._suction_columns.items():
                if name in sample:
                    theta[:, column] = sample[name]
            if self._push_columns is not None:
                heading = 2.0 * np.pi * u[:, len(ranges)]
                theta[:, self._push_columns] = sample["push"][:, None] * np.stack(
                    [np.cos(heading), np.sin(heading), np.zeros(k)], axis=1)
            sim.theta[rows] = theta
        mass = sample.get("mass", cfg.vehicle.mass)
        sim.mass[rows, 0] = mass
        if "motor_time_constant" in sample:
            # a lag shorter than a physics step is below what RK4 follows (MIN_LAG_STEPS): such a draw is no lag
            tau = sample["motor_time_constant"]
            tau = np.where(tau < MIN_LAG_STEPS * cfg.physics_dt, 0.0, tau)
            self.episode_parameters["motor_time_constant"][rows] = tau
            sim.timing[rows, Timing.motor_time_constant] = tau
        if "latency" in sample:
            total = np.round(sample["latency"] / cfg.physics_dt).astype(np.int64)
            self.command_delay[rows] = total // 2
            self.observation_delay[rows] = total - total // 2
            self._set_delays(rows)
        if "standoff" in sample:
            shift = sample["standoff"] - geometry.standoff
            sim.scene[rows] = geometry.scene_vector + shift[:, None] * geometry.scene_rate
            offset = shift[:, None] * geometry.p_rate
        else:
            offset = np.zeros((1, 3))
        self.ref_offset[rows] = offset

        # the control step the episode starts at: 0, or the drawn start_time along the reference
        start = (np.zeros(k, dtype=np.int64) if "start_time" not in sample else
                 np.clip(np.rint(sample["start_time"] / cfg.control_dt).astype(np.int64), 0, cfg.n_steps - 1))
        spread = np.reshape(np.asarray(spread, dtype=float), (-1, 1))
        perturb = (2.0 * u[:, len(ranges) + pushed:] - 1.0) * spread
        p_reference = self._ref_p[start] + offset
        p0 = p_reference + perturb[:, 0:3] * task.start_position_noise
        v0 = self._ref_v[start] + perturb[:, 3:6] * task.start_velocity_noise
        tilt = perturb[:, 6:9] * task.start_attitude_noise
        tilt[:, 2] += self._yaw
        q = euler_xyz_to_quat_rows(tilt)
        x = np.empty((k, STATE_SIZE))
        x[:, StateIndex.p_world] = p0
        x[:, StateIndex.q_body_to_world] = q
        x[:, StateIndex.v_world] = v0
        x[:, StateIndex.omega_body] = 0.0
        x[:, StateIndex.rotor_thrusts] = np.reshape(mass * (GRAVITY / 4.0), (-1, 1))
        self._keep_start_clear(x, p_reference, sim.scene[rows])
        sim.x[rows] = x
        self.R[rows], self.distances[rows] = self._geometry(x, sim.scene[rows])
        if self.surfaces is not None:
            self._query_surfaces(rows)
            self.surface_contact[rows] = False
        self.step_index[rows] = start
        self.previous_action[rows] = 0.0
        self.collisions[rows] = 0
        self.command[rows] = 0.0
        self.surface[rows] = 0
        self.strayed[rows] = False
        self.forces[rows] = 0.0
        self.rotor_suction[rows] = 0.0
        self._reset_conditions(rows, x, sample)

    def _keep_start_clear(self, x: np.ndarray, p_reference: np.ndarray, scene: np.ndarray) -> None:
        """Mirror starts ``x`` (in place) that lie closer than :data:`START_CLEARANCE` to a plane back out across that
        clearance, along the plane's normal (a start ``c`` from the plane goes to ``2 START_CLEARANCE - c``: the
        perturbation's spread folded, with no pile of starts at one distance); a start whose unperturbed state (at
        ``p_reference``, level, at the task's yaw) is closer than that keeps the unperturbed start's clearance."""
        sim = self.simulator
        clearance, normals = sim.clearances(x, scene)
        if np.all(clearance >= START_CLEARANCE):  # the usual reset: nothing to mirror, no unperturbed start to look at
            return
        reference = x.copy()
        reference[:, StateIndex.p_world] = p_reference
        reference[:, StateIndex.q_body_to_world] = euler_xyz_to_quat_rows(
            np.stack([np.zeros(len(x)), np.zeros(len(x)), np.full(len(x), self._yaw)], axis=1))
        margin = np.minimum(sim.clearances(reference, scene)[0], START_CLEARANCE)
        for attempt in range(4):  # one plane at a time: a start mirrored from a wall can come nearer the ground
            if attempt:
                clearance, normals = sim.clearances(x, scene)
            short = np.clip(margin - clearance, 0.0, None)
            if not np.any(short > 1e-12):
                return
            # mirrored, and in the last pass only brought to the clearance (two planes closer than the spread)
            shift = (2.0 if attempt < 3 else 1.0) * short + 1e-9 * (short > 0)
            x[:, StateIndex.p_world] += np.einsum("kap,kp->ka", normals, shift)

    def _reset_conditions(self, rows: np.ndarray | slice, x: np.ndarray, sample: dict[str, np.ndarray]) -> None:
        """A new episode's past for the delay lines, its sensing biases and its turbulence."""
        k = x.shape[0]
        if self._commands is not None and self._observed is not None:  # before the first command: hover
            self._commands.fill(rows, np.repeat(self._hover_command, k, axis=0))
            self._observed.fill(rows, x)
        if self._sensing is not None:
            self._sensing.reset(rows, self.streams.normal(rows, SensingErrors.RESET_NORMALS),
                                sample.get("sensing_scale", 1.0))
        if self._turbulence is not None:
            self._turbulence.reset(rows, self.streams.normal(rows, TurbulenceState.NORMALS),
                                   sample.get("gust_scale", 1.0))
            gust = self._turbulence.gust_world()[rows]
            for columns in self._wind_columns:  # the effect's own steady wind, the conditions' and the gust
                self.simulator.theta[rows, columns] = self._theta0[columns] + self._mean_wind + gust
        else:
            for columns in self._wind_columns:
                self.simulator.theta[rows, columns] = self._theta0[columns] + self._mean_wind
        if not self.ideal_observation:
            self._estimate(rows, x)

    # ------------------------------------------------------------------ step
    def step(self, actions: np.ndarray, active: np.ndarray | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Advance every row one control step with ``actions (n, 4)`` (checked, float64).

        ``active``: rows whose random streams advance (default all); the vector env passes
        the rows it is not about to reset, so their draws match a single env's.
        Returns ``reward, terminated, truncated`` (arrays of ``n``).
        """
        cfg, sim = self.config, self.simulator
        a = np.minimum(np.maximum(actions, -1.0), 1.0)
        command = self._mapping.to_physical(a)
        if cfg.noise:
            command += self.streams.step_normals(4, active) * self._noise_std
        if self._commands is not None:  # the rotors act on commands issued some steps ago
            self._commands.push(command)
            whole = self.command_delay // cfg.physics_substeps
            sim.u[:] = self._commands.read(whole)
            sim.u_previous[:] = self._commands.read(whole + 1)
        else:
            sim.u[:] = command
        if self._turbulence is not None:
            self._turbulence.step(self.streams.step_normals(TurbulenceState.NORMALS, active))
            gust = self._turbulence.gust_world()
            for columns in self._wind_columns:
                sim.theta[:, columns] = self._theta0[columns] + self._mean_wind + gust
        sim.step()
        sim.x[:] = sim.x_next
        self.R[:] = sim.R
        self.distances[:] = sim.distances
        self.forces[:] = sim.forces
        self.rotor_suction[:] = sim.rotor_suction
        if self.surfaces is not None:
            self._body_contacts(self._query_surfaces(slice(None)))
        self.command[:] = command
        self.step_index += 1
        if not self.ideal_observation:
            if self._observed is not None:
                self._observed.push(sim.x_observed)
                x_seen = self._observed.read(self.observation_delay // cfg.physics_substeps)
            else:
                x_seen = sim.x
            if self._sensing is not None:
                self._sensing.step(self.streams.step_normals(SensingErrors.STEP_NORMALS, active), active)
            self._estimate(slice(None), x_seen)

        touching = sim.penetrations > 0.0
        contact = touching.any(axis=1)
        self.surface[:] = np.where(contact, self._plane_codes[np.argmax(touching, axis=1)] if touching.shape[1]
                                   else 0, 0)
        if self.surfaces is not None:
            self.surface[self.surface_contact & ~contact] = 1 + SURFACES.index("structure")
            contact |= self.surface_contact
        self.collisions += contact

        x = sim.x
        i = self.step_index
        w = cfg.reward_weights
        p_error = x[:, StateIndex.p_world] - (self._ref_p[i] + self.ref_offset)
        v_error = x[:, StateIndex.v_world] - self._ref_v[i]
        error = np.sqrt((p_error * p_error).sum(axis=1))
        omega = x[:, StateIndex.omega_body]
        change = a - self.previous_action
        reward = (w["alive"] - w["position"] * error
                  - w["velocity"] * np.sqrt((v_error * v_error).sum(axis=1))
                  - w["smoothness"] * (change * change).sum(axis=1)
                  - w["body_rate"] * (omega * omega).sum(axis=1))
        if w["wall_normal"]:
            normal = self._nearest_surface(self.distances, self.surface_distance, self.surface_normal,
                                           self.simulator.scene)[1]
            reward -= w["wall_normal"] * np.abs((p_error * normal).sum(axis=1))
        strayed = ~(error <= cfg.max_tracking_error)  # also catches a NaN state
        reward -= cfg.collision_penalty * (contact | strayed)
        terminated = strayed | (contact & cfg.terminate_on_collision)
        truncated = ~terminated & (i >= cfg.n_steps)
        self.strayed[:] = strayed
        self.previous_action[:] = a
        return reward, terminated, truncated

    # ------------------------------------------------------------------ what the agent and the user see
    def observations(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """Observations of ``rows`` (default all), ``(k, 48)`` float32 (layout: :mod:`wall_env.observation`)."""
        f = OBSERVATION_FIELDS
        x = self.x_estimate[rows]
        i = self.step_index[rows]
        n = x.shape[0]
        ref = self._ref_table[i]  # p_ref, v_ref, preview
        obs = np.empty((n, OBSERVATION_SIZE), dtype=np.float32)
        obs[:, f["p_world"]] = x[:, StateIndex.p_world]
        obs[:, f["v_world"]] = x[:, StateIndex.v_world]
        obs[:, f["R_body_to_world"]] = self.R_estimate[rows][:, _ROW_MAJOR]
        obs[:, f["omega_body"]] = x[:, StateIndex.omega_body]
        obs[:, f["p_error"]] = x[:, StateIndex.p_world] - (ref[:, 0:3] + self.ref_offset[rows])
        obs[:, f["v_error"]] = x[:, StateIndex.v_world] - ref[:, 3:6]
        obs[:, f["reference_preview"]] = ref[:, 6:]
        clearance, normal = self._nearest_surface(self.distances_estimate[rows], self.surface_distance_estimate[rows],
                                                  self.surface_normal_estimate[rows], self.simulator.scene[rows])
        # a rotor with no surface within the query's reach reads the reach
        reach = min(self.surfaces.reach, CLEARANCE_CAP) if self.surfaces is not None else CLEARANCE_CAP
        obs[:, f["rotor_clearance"]] = np.minimum(clearance, reach)
        obs[:, f["wall_normal"]] = normal
        obs[:, f["previous_action"]] = self.previous_action[rows]
        obs[:, OBSERVATION_FIELDS["time"].start] = i * self.config.control_dt
        return obs

    def _nearest_surface(self, plane_distances: np.ndarray, surface_distance: np.ndarray, surface_normal: np.ndarray,
                         scene: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each rotor's distance to its nearest wall plane or body surface ``(k, 4)`` (``inf`` where none is known)
        and the outward normal of the surface nearest to any rotor ``(k, 3)`` (zeros where none is known), from
        the rows' plane distances ``(k, 4 * walls)`` and body-surface distances and normals (true or estimated)."""
        if self.surfaces is not None:  # planes and bodies: each rotor's nearest of all
            return self._clearance(plane_distances, surface_distance, surface_normal, scene)
        k = plane_distances.shape[0]
        if not self._n_walls:
            return np.full((k, 4), np.inf), np.zeros((k, 3))
        if self._n_walls == 1:
            return plane_distances, scene[:, 3:6]
        d = plane_distances.reshape(k, 4, self._n_walls)  # [row, rotor, wall]
        nearest = np.argmin(d.min(axis=1), axis=1)
        normals = scene[:, : 6 * self._n_walls].reshape(k, self._n_walls, 2, 3)[:, :, 1]
        return d.min(axis=2), normals[np.arange(k), nearest]

    def _clearance(self, plane_distances: np.ndarray, surface_distance: np.ndarray, surface_normal: np.ndarray,
                   scene: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each rotor's distance to its nearest plane or body surface ``(k, 4)`` (``inf`` where neither is known:
        no wall, and no body within the query's reach) and the outward normal of the surface nearest to any
        rotor ``(k, 3)`` (zeros where none is known)."""
        k = surface_distance.shape[0]
        d = surface_distance.copy()
        normal = surface_normal.copy()
        if self._n_walls:
            planes = plane_distances.reshape(k, 4, self._n_walls)  # [row, rotor, wall]
            nearest_wall = np.argmin(planes, axis=2)
            closer = planes.min(axis=2) < d
            wall_normals = scene[:, : 6 * self._n_walls].reshape(k, self._n_walls, 2, 3)[:, :, 1]
            normal = np.where(closer[:, :, None], wall_normals[np.arange(k)[:, None], nearest_wall], normal)
            d = np.where(closer, planes.min(axis=2), d)
        return d, normal[np.arange(k), np.argmin(d, axis=1)]

    def infos(self) -> dict[str, Any]:
        """The info of every row as arrays (keys: see :mod:`wall_env.env`)."""
        x = self.simulator.x.copy()  # one copy: the state entries below are views of it
        i = self.step_index
        n = self.n
        forces = self.forces.reshape(n, -1, 3).copy()  # [row, effect, axis]
        suction = forces[:, self._suction_index] if self._suction_index is not None else np.zeros((n, 3))
        nearest = self._nearest_surface(self.distances, self.surface_distance, self.surface_normal, self.simulator.scene)[0]
        clearance = nearest.min(axis=1) - self.config.vehicle.duct_radius  # inf where no surface is known
        return {
            "time": i * self.config.control_dt,
            "p_world": x[:, StateIndex.p_world],
            "q_body_to_world": x[:, StateIndex.q_body_to_world],
            "v_world": x[:, StateIndex.v_world],
            "omega_body": x[:, StateIndex.omega_body],
            "rotor_thrusts": x[:, StateIndex.rotor_thrusts],
            "p_ref": self._ref_p[i] + self.ref_offset,
            "v_ref": self._ref_v[i],
            "suction_force_world": suction,
            "rotor_suction_world": self.rotor_suction.reshape(n, 4, 3).copy(),
            "effect_forces_world": {name: forces[:, k] for k, name in enumerate(self._effect_names)},
            "collision": self.surface > 0,
            "collision_surface": _NO_SURFACE[self.surface],
            "collisions": self.collisions.copy(),
            "wall_clearance": clearance,
            "command": self.command.copy(),
            "strayed": self.strayed.copy(),
        }
