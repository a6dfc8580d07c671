"""Shared command line of the comparison scripts: the chain of `substep bench --compare`.

The chain: `dofs` floors of mass `mass` [kg] on springs of stiffness `stiffness` [N/m] (floor 1
on the fixed base), Rayleigh damping C = alpha M + beta K, Newmark average acceleration
(gamma = 1/2, beta = 1/4) with time step `dt`, ground acceleration a_g(t) = sin(2 pi t) [m/s^2].
Each script prints one JSON line: {"tool": ..., "us_per_step": ..., ...} or {"skipped": reason}.
"""

import argparse
import json
import sys


def parse_args(description):
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--dofs", type=int, default=5000)
    p.add_argument("--steps", type=int, default=1000)
    p.add_argument("--dt", type=float, default=0.01)
    p.add_argument("--mass", type=float, default=1.0e5)
    p.add_argument("--stiffness", type=float, required=True)
    p.add_argument("--alpha", type=float, required=True)
    p.add_argument("--beta", type=float, required=True)
    return p.parse_args()


def skip(reason):
    print(json.dumps({"skipped": reason}))
    sys.exit(0)


def report(**fields):
    print(json.dumps(fields))
