"""Shared command line and output of the comparison scripts run by `substep bench --compare`.

Every script runs monolithic Newmark (average acceleration, gamma = 1/2, beta = 1/4) from rest
under the ground acceleration a_g(t) = sin(2 pi t) [m/s^2], the load of step i + 1 being
-M iota a_g(t_{i+1}), on the model substep describes:
* `--mtx DIR`: M.mtx, C.mtx, K.mtx and influence.mtx written by substep (the frames), or
* `--dofs/--mass/--stiffness/--alpha/--beta`: the uniform shear chain (floor 1 on the base,
  Rayleigh C = alpha M + beta K), for tools that build their own model (OpenSees).
First `--check-steps` steps: the displacement of DOF `--roof` (0-based) after each is reported
(substep refuses to time a tool whose response differs). Then `--batches` batches of
`--batch-steps` steps, each timed in CPU time of the process (time.process_time), reported per
step in microseconds. One JSON line: {"tool", "roof_u", "cpu_us_per_batch", ...} or
{"skipped": reason}.
"""

import argparse
import json
import math
import sys


def parse_args(description):
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--mtx", default=None)
    p.add_argument("--dofs", type=int, default=5000)
    p.add_argument("--mass", type=float, default=1.0e5)
    p.add_argument("--stiffness", type=float, default=None)
    p.add_argument("--alpha", type=float, default=None)
    p.add_argument("--beta", type=float, default=None)
    p.add_argument("--roof", type=int, default=None)
    p.add_argument("--dt", type=float, default=0.01)
    p.add_argument("--check-steps", type=int, default=50)
    p.add_argument("--batches", type=int, default=5)
    p.add_argument("--batch-steps", type=int, default=20)
    p.add_argument("--solver", default=None)
    return p.parse_args()


def ag(i, dt):
    return math.sin(2 * math.pi * i * dt)


def skip(reason):
    print(json.dumps({"skipped": reason}))
    sys.exit(0)


def report(**fields):
    print(json.dumps(fields))
