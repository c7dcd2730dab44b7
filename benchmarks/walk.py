"""The walk of a command through the packages: which rooms a call passes on its way
from the command line into the numerics.

Runs `piecs-bayes ARGS` in this process under a profiler hook and records, for every
call made inside piecs_bayes, the chain of top-level packages on its stack
(consecutive frames of one package counted once; what an import runs, and `errors`
and `_config`, the floor every room stands on, left out). Prints each distinct chain
with how often it was entered, the longest one, and any chain that comes back to a
package it left (a call upward, or a callback into a room above). Exit 1 when a chain is longer than
`--max` or returns to a package.

    .venv/bin/python benchmarks/walk.py --max 5 -- fit data/demo/study.toml --out /tmp/w
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter

FLOOR = {"errors", "_config"}


def _package(frame) -> str | None:
    name = frame.f_globals.get("__name__", "")
    if name == "piecs_bayes" or not name.startswith("piecs_bayes."):
        return None
    top = name.split(".")[1]
    return None if top in FLOOR else top


def walk(argv: list[str]) -> tuple[Counter, int]:
    """(chains -> calls, exit code of the command)."""
    from piecs_bayes.cli import main

    chains: Counter = Counter()
    paths: dict[int, tuple[str, ...]] = {}

    def hook(frame, event, _arg):
        if event != "call":
            if event == "return":
                paths.pop(id(frame), None)
            return
        top = _package(frame)
        if top is None:
            return
        parent, back = (), frame.f_back
        while back is not None:
            if id(back) in paths:
                parent = paths[id(back)]
                break
            if back.f_globals.get("__name__", "").startswith("importlib"):
                return  # run by an import (module and class bodies): no walk
            back = back.f_back
        path = parent if parent and parent[-1] == top else parent + (top,)
        paths[id(frame)] = path
        chains[path] += 1

    sys.setprofile(hook)
    try:
        code = main(argv)
    except SystemExit as e:  # argparse's --help and errors
        code = e.code if isinstance(e.code, int) else 1
    finally:
        sys.setprofile(None)
    return chains, int(code or 0)


def report(chains: Counter, limit: int) -> int:
    returns = [c for c in chains if len(set(c)) < len(c)]
    longest = max(chains, key=len, default=())
    # the maximal chains: those that are no prefix of another
    maximal = [c for c in chains if not any(d != c and d[: len(c)] == c for d in chains)]
    for c in sorted(maximal, key=lambda c: (-len(c), c)):
        print(f"{len(c)}  {' > '.join(c)}")
    print(f"chains: {len(chains)}, maximal: {len(maximal)}, longest: {len(longest)} "
          f"packages ({' > '.join(longest)}), returns to a package it left: {len(returns)}")
    for c in returns:
        print(f"  returns: {' > '.join(c)}")
    return 1 if len(longest) > limit or returns else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max", type=int, default=5, help="most packages on one chain")
    ap.add_argument("command", nargs=argparse.REMAINDER, help="-- then piecs-bayes arguments")
    a = ap.parse_args()
    argv = a.command[1:] if a.command[:1] == ["--"] else a.command
    chains, code = walk(argv)
    if code:
        print(f"the command exited with {code}", file=sys.stderr)
        return code
    return report(chains, a.max)


if __name__ == "__main__":
    sys.exit(main())
