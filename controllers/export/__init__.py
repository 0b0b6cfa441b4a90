"""MPC and SC-MPC exported as C, to fly on a flight computer without Python, CasADi or this package.

::

    from controllers import SCMPC
    from controllers.export import NativeController, build, export_controller

    policy = SCMPC.from_env(env, k_s=4.1, d_thr=0.132)
    export_controller(policy, "out/scmpc")      # C files, Makefile, export.json
    build("out/scmpc")                          # make: libwi_controller.a/.so, wi_bench
    native = NativeController("out/scmpc", policy)
    native.follow(env)
    action, _ = native.predict(obs)             # the C library's action, through ctypes

:mod:`controllers.export.c_code` writes the folder (the code CasADi generates from the
control step the Python controller compiles, a hand-written entry point ``wi_step`` and its
header), :mod:`controllers.export.native` builds it and flies the library through ctypes,
:mod:`controllers.export.timing` times ``wi_step`` with a C timing loop on a recorded flight.
"""

from controllers.export.c_code import export_controller
from controllers.export.native import NativeController, build

__all__ = ["export_controller", "build", "NativeController"]
