"""Where each effect's parameters sit in the packed vector a fit moves, for one flight or several.

A fit moves one vector ``theta``; the effects read their own parameter vectors from it.
:class:`ParameterLayout` is the one place that packs and splits it:

- each effect (a candidate key such as ``quadratic_drag[wind]`` and its template
  :class:`~wall_env.effects.Effect`) owns a block of entries, in the order given;
- across several flights, the parameters named in :data:`CONDITIONS` (a steady wind) are
  the flight's own: each flight gets its own copy, while every other parameter (the
  vehicle's and the aerodynamics', a drag coefficient) is shared. One flight at one wind
  cannot tell a drag coefficient from the wind speed (only ``C w^2`` is determined); with
  flights at several winds the shared coefficient and each wind are;
- entries can be *fixed* (held at a value, not fitted): an undetermined entry nulled, a
  nuisance parameter a cross-validation fold holds.

``layout.split(theta, flight)`` gives each effect's own vector for one flight,
``layout.effects(theta, flight)`` the effects with those values, ``layout.index[e][f]``
the packed entries of effect ``e`` for flight ``f`` (for Jacobian columns), and
``layout.labels()`` names every entry (``quadratic_drag[wind].w[0]@1`` for flight 1's).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wall_env.effects import Effect

__all__ = ["CONDITIONS", "ParameterLayout"]

#: parameter names that each flight has its own value of when several flights are fitted together
CONDITIONS = frozenset({"w"})


@dataclass(frozen=True)
class _Entry:
    effect: int  # index of the effect in the layout
    parameter: str  # the effect's parameter name
    component: int  # entry within the parameter (0 for scalars)
    flight: int | None  # the flight whose own copy this is, None when shared


class ParameterLayout:
    """The packed parameter vector of ``templates`` (keyed by ``keys``) over ``n_flights`` flights."""

    def __init__(self, keys: list[str], templates: list[Effect], n_flights: int = 1):
        if len(keys) != len(templates):
            raise ValueError("one key per template")
        self.keys = list(keys)
        self.templates = list(templates)
        self.n_flights = max(1, int(n_flights))
        entries: list[_Entry] = []
        index: list[list[np.ndarray]] = []
        for e, template in enumerate(self.templates):
            per_flight: list[list[int]] = [[] for _ in range(self.n_flights)]
            for p in template.parameters:
                own = self.n_flights > 1 and p.name in CONDITIONS
                for c in range(p.size):
                    if own:
                        for f in range(self.n_flights):
                            per_flight[f].append(len(entries))
                            entries.append(_Entry(e, p.name, c, f))
                    else:
                        position = len(entries)
                        entries.append(_Entry(e, p.name, c, None))
                        for f in range(self.n_flights):
                            per_flight[f].append(position)
            index.append([np.asarray(rows, dtype=int) for rows in per_flight])
        self._entries = entries
        #: ``index[e][f]``: packed entries of effect ``e``'s own vector for flight ``f``
        self.index = index
        self.size = len(entries)
        low, high, default = np.zeros(self.size), np.zeros(self.size), np.zeros(self.size)
        for e, template in enumerate(self.templates):
            lo, hi = template.param_bounds()
            for f in range(self.n_flights):
                low[index[e][f]], high[index[e][f]] = lo, hi
                default[index[e][f]] = template.param_vector()
        self.low, self.high, self.defaults = low, high, default

    # ------------------------------------------------------------------ packing
    def split(self, theta: np.ndarray, flight: int = 0) -> list[np.ndarray]:
        """Each effect's own parameter vector for ``flight``."""
        theta = np.asarray(theta, dtype=float)
        return [theta[rows[flight]] for rows in self.index]

    def effects(self, theta: np.ndarray, flight: int = 0) -> list[Effect]:
        """The templates with their values for ``flight`` (validated against their ranges)."""
        return [t.with_params(v) for t, v in zip(self.templates, self.split(theta, flight))]

    def pack(self, vectors: dict[str, np.ndarray] | None = None, base: np.ndarray | None = None) -> np.ndarray:
        """A packed vector from effects' own vectors by key (every flight gets the same), else ``base``,
        else the templates' values."""
        theta = self.defaults.copy() if base is None else np.asarray(base, dtype=float).copy()
        for e, key in enumerate(self.keys):
            if vectors and key in vectors:
                value = np.asarray(vectors[key], dtype=float)
                for rows in self.index[e]:
                    theta[rows] = value
        return theta

    def hold(self, theta: np.ndarray, held: dict[str, dict[int, float]]) -> np.ndarray:
        """Set the entries ``held`` (``{key: {entry of the effect's own vector: value}}``) in ``theta``, in place,
        on every flight; returns the mask of those packed entries."""
        mask = np.zeros(self.size, dtype=bool)
        for e, key in enumerate(self.keys):
            for entry, value in held.get(key, {}).items():
                for rows in self.index[e]:
                    mask[rows[entry]], theta[rows[entry]] = True, value
        return mask

    def dicts(self, vector: np.ndarray, flight: int = 0) -> list[dict]:
        """Per effect, ``vector``'s entries (values or standard errors) as the effect's named parameters."""
        return [t.params_dict(v) for t, v in zip(self.templates, self.split(vector, flight))]

    def labels(self) -> list[str]:
        """A name for every packed entry: ``key.parameter[component]``, with ``@flight`` on a flight's own."""
        out = []
        for entry in self._entries:
            template = self.templates[entry.effect]
            size = next(p.size for p in template.parameters if p.name == entry.parameter)
            name = f"{self.keys[entry.effect]}.{entry.parameter}" + (f"[{entry.component}]" if size > 1 else "")
            out.append(name + ("" if entry.flight is None else f"@{entry.flight}"))
        return out

    def effect_of(self, position: int) -> int:
        """The effect that owns packed entry ``position``."""
        return self._entries[position].effect

    def flight_entries(self, flight: int) -> np.ndarray:
        """Mask of the entries that are ``flight``'s own (its conditions)."""
        return np.array([entry.flight == flight for entry in self._entries], dtype=bool)

    def shared_entries(self) -> np.ndarray:
        """Mask of the entries every flight shares."""
        return np.array([entry.flight is None for entry in self._entries], dtype=bool)

    def entries_of(self, effect: int) -> np.ndarray:
        """Mask of the packed entries of effect ``effect`` (over all flights)."""
        return np.array([entry.effect == effect for entry in self._entries], dtype=bool)

    def has_conditions(self) -> bool:
        return any(entry.flight is not None for entry in self._entries)

    def __repr__(self) -> str:
        return f"ParameterLayout({self.keys}, n_flights={self.n_flights}, size={self.size})"
