#!/usr/bin/env python3
"""OpenSees interoperability check for substep's OpenFresco server.

A 1-DOF oscillator (node 2, mass m, node 1 fixed) under a ground acceleration is analysed
five times with openseespy (Newmark average acceleration, algorithm Linear):

  native          zeroLength element with an Elastic(k) material
  generic_element genericClient element on nodes 1 and 2 ('-dof 1' at each), hosted by a
                  substep OpenFresco server with a 2x2 linear_element k [[1, -1], [-1, 1]]
  generic_sdof    genericClient element on node 2 only ('-dof 1'), hosted by a substep server
                  with a linear_sdof spring (mass None) of stiffness k
  native_damped   zeroLength with Elastic(k) and Viscous(c, 1) in parallel
  generic_damped  genericClient on nodes 1 and 2, hosted by a linear_element with K and C
                  (damping reported to the client, action 14)

The substep servers are started by the Rust test (crates/substep/tests/site.rs,
opensees_generic_client_matches_native_element), which passes their ports. Output: one line
per run, the name followed by the displacement of node 2 after every step (repr floats).
"""

import argparse
import math
import sys

import openseespy.opensees as ops


def ground_motion(dt, steps):
    """A decaying chirp [m/s^2], sampled at t = i dt, i = 0..steps."""
    out = []
    for i in range(steps + 1):
        t = i * dt
        out.append(2.0 * math.sin(2.0 * math.pi * (0.6 * t + 0.5 * t * t)) * math.exp(-0.3 * t))
    return out


def run(kind, a, ag):
    ops.wipe()
    ops.model('basic', '-ndm', 1, '-ndf', 1)
    ops.node(1, 0.0)
    ops.node(2, 0.0)
    ops.fix(1, 1)
    ops.mass(2, a.m)
    if kind == 'native':
        ops.uniaxialMaterial('Elastic', 1, a.k)
        ops.element('zeroLength', 1, 1, 2, '-mat', 1, '-dir', 1)
    elif kind == 'native_damped':
        ops.uniaxialMaterial('Elastic', 1, a.k)
        ops.uniaxialMaterial('Viscous', 2, a.c, 1.0)
        ops.element('zeroLength', 1, 1, 2, '-mat', 1, 2, '-dir', 1, 1)
    elif kind == 'generic_element':
        ops.element('genericClient', 1, '-node', 1, 2, '-dof', 1, '-dof', 1, '-server', a.port_element, '127.0.0.1')
    elif kind == 'generic_sdof':
        ops.element('genericClient', 1, '-node', 2, '-dof', 1, '-server', a.port_sdof, '127.0.0.1')
    elif kind == 'generic_damped':
        ops.element('genericClient', 1, '-node', 1, 2, '-dof', 1, '-dof', 1, '-server', a.port_damped, '127.0.0.1')
    else:
        raise ValueError(kind)
    ops.timeSeries('Path', 1, '-dt', a.dt, '-values', *ag)
    ops.pattern('UniformExcitation', 1, 1, '-accel', 1)
    ops.constraints('Plain')
    ops.numberer('Plain')
    ops.system('FullGeneral')
    ops.algorithm('Linear')
    ops.integrator('Newmark', 0.5, 0.25)
    ops.analysis('Transient')
    u = []
    for i in range(a.steps):
        if ops.analyze(1, a.dt) != 0:
            raise RuntimeError(f'{kind}: analysis failed at step {i + 1}')
        u.append(ops.nodeDisp(2, 1))
    ops.wipe()  # deletes the genericClient element: it sends action 99 and disconnects
    return u


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--k', type=float, default=4.0e4, help='spring stiffness [N/m]')
    p.add_argument('--c', type=float, default=120.0, help='dashpot [N s/m]')
    p.add_argument('--m', type=float, default=100.0, help='mass [kg]')
    p.add_argument('--dt', type=float, default=0.01, help='time step [s]')
    p.add_argument('--steps', type=int, default=500)
    p.add_argument('--port-element', type=int, help='server hosting the 2-node linear_element')
    p.add_argument('--port-sdof', type=int, help='server hosting the 1-node linear_sdof spring')
    p.add_argument('--port-damped', type=int, help='server hosting the damped 2-node linear_element')
    a = p.parse_args()
    ag = ground_motion(a.dt, a.steps)
    runs = ['native', 'native_damped']
    if a.port_element:
        runs.append('generic_element')
    if a.port_sdof:
        runs.append('generic_sdof')
    if a.port_damped:
        runs.append('generic_damped')
    for kind in runs:
        u = run(kind, a, ag)
        print(kind, ' '.join(repr(x) for x in u))
        sys.stdout.flush()


if __name__ == '__main__':
    main()
