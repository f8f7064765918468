#!/usr/bin/env python3
"""tools/bench_peers.py's CountSearch on count functions of the kinds the peer bench meets (seconds, no data):
a clustering's 1/c^2, the labels' flatter fall on coarse levels, sloppy's most triangles (a plateau), a
uniform grid's count that is not monotone in the cell size.
Each must end within the tolerance in the steps given, or stop as stuck where no x can give the count."""
import math
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tools"))
from bench_peers import CountSearch  # noqa: E402


def search(f, want, x0, grows, steps=12, tol=0.05):
    s = CountSearch(want, x0, grows)
    for k in range(1, steps + 1):
        x = s.x
        got = f(x)
        s.add(x, got)
        if abs(got - want) <= tol * want:
            return "within", k
        if s.stuck:
            return "stuck", k
    return "out", steps


failures = []


def expect(name, got, outcome, most):
    ok = got[0] == outcome and got[1] <= most
    print(f"{'ok  ' if ok else 'FAIL'} {name}: {got[0]} after {got[1]} steps (want {outcome} in at most {most})")
    if not ok:
        failures.append(name)


expect("1/c^2 cell size", search(lambda c: int(1e6 / c ** 2), 5000, 1.0, False), "within", 3)
expect("1/c^3.5 cell size", search(lambda c: int(1e6 / c ** 3.5), 5000, 1.0, False), "within", 4)
# the labels on a coarse level: the count falls as c^-0.4 (city-9 level 3 needed 5 steps)
expect("flat c^-0.4", search(lambda c: int(2e5 / c ** 0.4 + 100), 5000, 1.0, False), "within", 6)
# sloppy: at most 445,549 whatever the target (city-9 levels 0 and 1)
expect("sloppy plateau", search(lambda t: int(min(t * 0.3, 445549)), 5405332, 5405332, True), "stuck", 3)
# steps of 1.43x: stuck once the target has grown by a factor 4 (the 5th step)
expect("sloppy plateau, small steps", search(lambda t: int(min(t, 445549)), 638055, 638055, True), "stuck", 5)
expect("sloppy below its most", search(lambda t: int(min(t * 0.3, 445549)), 124198, 124198, True), "within", 3)
# a uniform grid: the count wobbles +-30 % with the cell size (not monotone)
expect("not monotone", search(lambda c: int(1e6 / c ** 2 * (1 + 0.3 * math.sin(40 * c))), 5000, 1.0, False),
       "within", 8)
sys.exit(1 if failures else 0)
