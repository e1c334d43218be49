"""Runs the ground-station tests on a few workers at once, each test (or each class that
shares a board between its tests) in its own `python3 -m unittest` process, and fails when any
of them fails.

Each test serves its own board (`board.ServedBoard`: its own `fcu-pil serve`, port and flash
file), and a served board is paced to the wall clock and takes about a tenth of a core: run one
after the other, the tests leave the machine mostly idle and CI mostly waiting. A class with a
`setUpClass` serves one board for all its tests and runs as one job; any other class runs test by
test. Jobs are handed out as workers free up, so a slow one does not hold up the others.

    python3 run_parallel.py [--jobs N] MODULE...   # e.g. test_link test_mavproxy
"""

import argparse
import concurrent.futures
import importlib
import inspect
import os
import subprocess
import sys
import time
import unittest


def jobs(modules):
    """`module.Class` of every TestCase class with a `setUpClass` of its own, and
    `module.Class.test` of every test of the others, in the modules' order."""
    found = []
    loader = unittest.TestLoader()
    for order, name in enumerate(modules):
        module = importlib.import_module(name)
        for cls_name, cls in inspect.getmembers(module, inspect.isclass):
            if not (issubclass(cls, unittest.TestCase) and cls.__module__ == name):
                continue
            line = inspect.getsourcelines(cls)[1]
            if "setUpClass" in vars(cls):
                found.append((order, line, f"{name}.{cls_name}"))
            else:
                found.extend((order, line, f"{name}.{cls_name}.{test}") for test in loader.getTestCaseNames(cls))
    return [qualified for _, _, qualified in sorted(found)]


def run(qualified):
    start = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-m", "unittest", "-v", qualified],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        cwd=os.path.dirname(os.path.abspath(__file__)),
    )
    return qualified, proc.returncode, proc.stdout, time.monotonic() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=3, help="jobs run at once (default 3)")
    parser.add_argument("modules", nargs="+")
    args = parser.parse_args()
    if args.jobs < 1:
        parser.error(f"--jobs {args.jobs}: at least 1")
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    todo = jobs(args.modules)
    if not todo:
        parser.error(f"no test class in {' '.join(args.modules)}")
    failed = []
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
        for qualified, rc, output, seconds in pool.map(run, todo):
            print(f"--- {qualified}: {'ok' if rc == 0 else 'FAILED'} in {seconds:.0f} s")
            print(output, end="" if output.endswith("\n") else "\n")
            if rc != 0:
                failed.append(qualified)
    if failed:
        print(f"FAILED: {' '.join(failed)}")
        return 1
    print(f"all {len(todo)} jobs passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
