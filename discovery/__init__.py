"""Model discovery: find where simulation and flight data disagree, name the missing effect, fit it.

A user with a new vehicle, wall or ceiling has flight logs that their simulation does
not reproduce. :class:`Discovery` finds *where* the force residual of the nominal
model (paper Eq. 28) is significant, says *what* effect of the effects library
explains it (each candidate fitted by least squares with the library's own CasADi
Jacobians, ranked on held-out data with a parsimony price, greedy forward
selection), writes the *fix* (a model file the env and SC-MPC load) and the *proof*
(held-out force and open-loop prediction gaps before and after, plots, and a
closed-loop check of SC-MPC built from the discovered model)::

    from discovery import Discovery, read_log

    found = Discovery().fit([read_log("flight.csv")])
    found.effects_, found.gap_before_, found.gap_after_
    found.model_.save("model.json")
    found.predict(read_log("other.csv")), found.score(read_log("other.csv"))

Command line (:mod:`wall_inspector`): ``wall-inspector fly`` records logs from the simulator,
``wall-inspector import-log`` converts PX4 ULogs and ROS 2 bags and ``wall-inspector discover``
runs the workflow. The log format is documented in
:mod:`discovery.flight_log`; the modules, in the order of the workflow:
:mod:`~discovery.flight_log`, :mod:`~discovery.coverage`, :mod:`~discovery.differentiation`,
:mod:`~discovery.aero_eval`, :mod:`~discovery.residuals`, :mod:`~discovery.prediction`,
:mod:`~discovery.regressors`, :mod:`~discovery.layout`, :mod:`~discovery.fitting`,
:mod:`~discovery.selection` (with :mod:`~discovery.motor_lag`, a lag of the rotors behind the
logged thrust, and :mod:`~discovery.thrust_map`, an affine thrust map), :mod:`~discovery.determination`,
:mod:`~discovery.cancelling`, :mod:`~discovery.wall_extent`, :mod:`~discovery.noise`,
:mod:`~discovery.unexplained`, :mod:`~discovery.standins`,
:mod:`~discovery.workflow`, :mod:`~discovery.report`, :mod:`~discovery.plots`,
:mod:`~discovery.closed_loop`, :mod:`~discovery.fly`, :mod:`~discovery.scenarios`;
beside them :mod:`~discovery.importers` (PX4 ULog and ROS 2 bags), :mod:`~discovery.coverage`
(what a flight can and cannot tell), :mod:`~discovery.determination` (only determined
parameters reach the model file) and :mod:`~discovery.hidden_effects` (hidden-effect logs
for ``wall-inspector bench-discover --acceptance``).
"""

from discovery.flight_log import FlightLog, LogFormatError, NominalVehicle, read_log, write_log
from discovery.workflow import Discovery

__all__ = ["Discovery", "FlightLog", "LogFormatError", "NominalVehicle", "read_log", "write_log"]
