"""Config construction: the declared (pydantic) configs of every registered scenario, built many times.

Rows, per registered scenario: its config with the defaults, with a sub-config given as a dict
(``body={"radius": 0.6}``, merged over the scenario's default body) and ``dataclasses.replace`` of one field;
``make(name)`` (the whole env, for scale) is timed over fewer rounds. Figures are mean microseconds per
construction over ``--rounds`` constructions (after one untimed warm-up).

Target: every config construction under 1 ms (1,000 us).

Run: ``.venv/bin/python benchmarks/bench_config.py [--rounds N] [--make-rounds M]``
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import argparse  # noqa: E402
import dataclasses  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from typing import Any  # noqa: E402

from common import fmt_num, machine_description, markdown_table  # noqa: E402

TARGET_US = 1000.0
"""Most microseconds a config construction may take."""


def mean_us(call: Callable[[], Any], rounds: int) -> float:
    """Mean wall microseconds of ``call()`` over ``rounds`` calls (one untimed call first)."""
    call()
    start = time.perf_counter()
    for _ in range(rounds):
        call()
    return (time.perf_counter() - start) / rounds * 1e6


def rows(rounds: int, make_rounds: int) -> list[list[str]]:
    """One table row per registered scenario."""
    import agentsim_env
    from agentsim_env.scenarios.registry import scenario_class, usable_scenarios

    out = []
    for name in usable_scenarios():
        cls = scenario_class(name).config_cls
        default = cls()
        times = [
            mean_us(cls, rounds),
            mean_us(lambda cls=cls: cls(body={"radius": 0.6}), rounds),
            mean_us(lambda d=default: dataclasses.replace(d, max_steps=123), rounds),
        ]
        made = mean_us(lambda name=name: agentsim_env.make(name), make_rounds) if make_rounds else float("nan")
        verdict = "yes" if max(times) < TARGET_US else "NO"
        made_cell = fmt_num(made) if make_rounds else "-"
        out.append([name, *(fmt_num(t) for t in times), made_cell, verdict])
    return out


def main() -> None:
    """Print the construction table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2000, help="constructions per config figure")
    parser.add_argument("--make-rounds", type=int, default=20, help="make(name) calls per scenario (0: skip)")
    args = parser.parse_args()
    print(machine_description())
    print()
    headers = ["scenario", "default (us)", "body dict (us)", "replace (us)", "make(name) (us)", "< 1 ms"]
    print(markdown_table(headers, rows(args.rounds, args.make_rounds)))


if __name__ == "__main__":
    main()
