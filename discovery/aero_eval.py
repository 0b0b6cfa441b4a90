"""Vectorised evaluation of an aerodynamic model's force and its parameter Jacobian over many samples.

Discovery evaluates the effects library's own CasADi definitions
(:meth:`wall_env.aero.AeroModel.function`) at thousands of logged states, and their
Jacobians with respect to the packed parameters ``theta`` for least squares. No
effect formula is written here: the force comes from the library's function and the
Jacobian is CasADi's derivative of it.

For speed the per-sample function is mapped over a fixed chunk of samples
(``Function.map``) and compiled to native code with :class:`wall_env.codegen.CompiledFunction`
(cached on disk, so only the first use on a machine pays the compile time); samples
are fed chunk by chunk. Without a C compiler the same mapped function runs in
CasADi's evaluator.

A scene with bodies (:mod:`wall_env.bodies`) gives every sample its own scene vector: the
planes, then each rotor's local surfaces at that sample's pose from PyBullet's query
(:class:`wall_env.surfaces.SurfaceQuery`, reaching as far as any threshold a fit may try),
read by the effects exactly as the simulator reads them.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from wall_env.aero import AeroModel
from wall_env.codegen import CompiledFunction
from wall_env.effects import make_effect
from wall_env.scene import Scene
from wall_env.vehicle import VehicleParams

__all__ = ["SampleStates", "ForceEvaluator", "CHUNK"]

CHUNK = 1024  # samples per native call


@dataclass(frozen=True)
class SampleStates:
    """Flight states at ``n`` samples, SI, frames in the names."""

    p_world: np.ndarray  # (n, 3) m
    R_body_to_world: np.ndarray  # (n, 3, 3)
    v_world: np.ndarray  # (n, 3) m/s
    omega_body: np.ndarray  # (n, 3) rad/s
    rotor_thrusts: np.ndarray  # (n, 4) N
    mass: float  # kg

    @property
    def n(self) -> int:
        return len(self.p_world)

    def take(self, index) -> SampleStates:
        return SampleStates(self.p_world[index], self.R_body_to_world[index], self.v_world[index],
                            self.omega_body[index], self.rotor_thrusts[index], self.mass)


@lru_cache(maxsize=128)
def _mapped(structure_key: tuple, rotors: tuple, scene_structure: tuple, gravity: float,
            jacobian: bool) -> CompiledFunction:
    model = AeroModel([make_effect(name, **dict(options)) for name, options in structure_key])
    f = model.structure_function(np.asarray(rotors), scene_structure, gravity)
    symbols = [ca.SX.sym(f.name_in(i), f.sparsity_in(i)) for i in range(f.n_in())]
    force = f(*symbols)[0]
    outputs = [force]
    if jacobian:
        theta = symbols[6]
        outputs.append(ca.densify(ca.reshape(ca.jacobian(force, theta), 3 * model.param_size, 1)))
    outputs = [ca.densify(o) for o in outputs]
    per_sample = ca.Function("effect_force_jac" if jacobian else "effect_force", symbols, outputs)
    # theta may differ per sample (one call serves models fitted on different folds); mass is shared by all
    # samples of a chunk, and so is the scene unless it has bodies (each sample then has its rotors' surfaces)
    per_sample_scene = len(scene_structure) > 3 and scene_structure[3] > 0
    mapped = per_sample.map(CHUNK, "serial")
    # MX keeps the map a loop in the generated code (SX would unroll CHUNK copies)
    p = ca.MX.sym("p", 3, CHUNK)
    R = ca.MX.sym("R", 3, 3 * CHUNK)
    v = ca.MX.sym("v", 3, CHUNK)
    w = ca.MX.sym("w", 3, CHUNK)
    f_rotor = ca.MX.sym("f", 4, CHUNK)
    mass = ca.MX.sym("mass")
    th = ca.MX.sym("theta", model.param_size, CHUNK)
    scene = ca.MX.sym("scene", symbols[7].numel(), CHUNK if per_sample_scene else 1)
    out = mapped(p, R, v, w, f_rotor, ca.repmat(mass, 1, CHUNK), th,
                 scene if per_sample_scene else ca.repmat(scene, 1, CHUNK))
    out = out if isinstance(out, (list, tuple)) else [out]
    name = f"discovery_{'jac' if jacobian else 'force'}"
    chunk_function = ca.Function(name, [p, R, v, w, f_rotor, mass, th, scene], list(out))
    return CompiledFunction(chunk_function)


SURFACE_REACH = 1.05  # m: each rotor's surfaces as far as the largest suction threshold (1 m) and a margin


@lru_cache(maxsize=8)
def _surface_query(scene: Scene, rotors: tuple) -> Any:
    from wall_env.surfaces import SurfaceQuery

    return SurfaceQuery(scene, VehicleParams(rotor_positions=rotors), SURFACE_REACH)


class ForceEvaluator:
    """Force (world frame, N) of an :class:`AeroModel` and its Jacobian with respect to ``theta``.

    ``ForceEvaluator(model, rotor_positions_body, scene, gravity)``; then
    ``force(states, theta) -> (n, 3)`` and ``force_and_jacobian(states, theta) ->
    ((n, 3), (n, 3, param_size))``. The scene's numbers may differ from call to call
    through :attr:`scene_vector`; its structure (walls, ground, ceiling) is fixed.
    """

    def __init__(self, model: AeroModel, rotor_positions_body: np.ndarray, scene: Scene, gravity: float):
        self.model = model
        self.param_size = model.param_size
        self.scene = scene
        self.scene_vector = scene.to_vector()
        key = (model.structure_key, tuple(map(tuple, np.asarray(rotor_positions_body, dtype=float))),
               scene.structure, float(gravity))
        self._key = key
        self._force: CompiledFunction | None = None
        self._jacobian: CompiledFunction | None = None

    @staticmethod
    def _packed(states: SampleStates) -> list[tuple[Any, ...]]:
        """Per-chunk input arrays, column-major as the compiled code wants them (cached on ``states``)."""
        cached = states.__dict__.get("_packed_chunks")
        if cached is not None:
            return cached
        n = states.n
        chunks = []
        for start in range(0, n, CHUNK):
            stop = min(start + CHUNK, n)
            index = np.arange(start, start + CHUNK)
            index[index >= stop] = stop - 1  # pad the last chunk with its last sample
            chunks.append((
                np.ravel(states.p_world[index].T, order="F"),
                np.ravel(np.concatenate(states.R_body_to_world[index], axis=1), order="F"),
                np.ravel(states.v_world[index].T, order="F"),
                np.ravel(states.omega_body[index].T, order="F"),
                np.ravel(states.rotor_thrusts[index].T, order="F"),
                index,
                stop - start,
            ))
        object.__setattr__(states, "_packed_chunks", chunks)
        return chunks

    def _run(self, function: CompiledFunction, states: SampleStates, theta: np.ndarray) -> list[np.ndarray]:
        n = states.n
        theta = np.asarray(theta, dtype=float)
        per_sample = theta.ndim == 2
        if not per_sample:
            shared = np.repeat(theta.reshape(-1, 1), CHUNK, axis=1).ravel(order="F")
        outputs: list[list[np.ndarray]] = []
        scenes = self._surface_chunks(states) if self.scene.has_bodies else None
        for chunk, (p, R, v, w, f, index, count) in enumerate(self._packed(states)):
            th = np.ravel(theta[index].T, order="F") if per_sample else shared
            scene = self.scene_vector if scenes is None else scenes[chunk]
            result = function(p, R, v, w, f, states.mass, th, scene)
            outputs.append([r.reshape(-1, CHUNK, order="F")[:, :count] for r in result])
        if n == 0:
            return [np.zeros((3, 0)), np.zeros((3 * self.param_size, 0))]
        return [np.concatenate([o[k] for o in outputs], axis=1) for k in range(len(outputs[0]))]

    def _surface_chunks(self, states: SampleStates) -> list[np.ndarray]:
        """Per chunk, every sample's scene vector (the planes, then its rotors' local surfaces), column-major;
        cached on ``states`` per scene."""
        cache = states.__dict__.setdefault("_surface_chunks", {})
        if self.scene not in cache:
            rotors = tuple(map(tuple, self._key[1]))
            surfaces = _surface_query(self.scene, rotors).rotor_surfaces_at(states.p_world, states.R_body_to_world)
            plane = self.scene_vector[: self.scene.structure.plane_size]
            vectors = np.hstack([np.tile(plane, (states.n, 1)), surfaces])
            cache[self.scene] = [np.ravel(vectors[index].T, order="F") for *_, index, _ in self._packed(states)]
        return cache[self.scene]

    def force(self, states: SampleStates, theta: np.ndarray) -> np.ndarray:
        """Force ``(n, 3)`` in the world frame; ``theta`` ``(param_size,)`` or one row per sample."""
        if self._force is None:
            self._force = _mapped(*self._key, False)
        return self._run(self._force, states, theta)[0].T

    def force_and_jacobian(self, states: SampleStates, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Force ``(n, 3)`` and its Jacobian ``(n, 3, param_size)`` with respect to ``theta``."""
        if self._jacobian is None:
            self._jacobian = _mapped(*self._key, True)
        force, jac = self._run(self._jacobian, states, theta)
        # CasADi's column-major reshape of the (3, p) Jacobian: entry (i, k) sits at row k * 3 + i
        jac = jac.T.reshape(-1, self.param_size, 3).transpose(0, 2, 1)
        return force.T, jac
