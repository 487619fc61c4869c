#!/usr/bin/env python
"""Compare two grids' ``results_cells.csv`` metric by metric, per tracker (step times and
versions aside): which trackers a version changed, and by how much. The code is
:mod:`dgpt_gym.benchmark.compare`.

    git show <old commit>:docs/results_cells.csv > /tmp/old.csv
    python scripts/compare_cells.py /tmp/old.csv docs/results_cells.csv
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dgpt_gym.benchmark.compare import compare_cells, comparison_markdown, read_cells  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("old", help="the earlier results_cells.csv")
    parser.add_argument("new", help="the later results_cells.csv")
    args = parser.parse_args(argv)
    try:
        old, new = read_cells(args.old), read_cells(args.new)
    except (FileNotFoundError, ValueError) as error:
        parser.error(str(error))
    print(comparison_markdown(compare_cells(old, new)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
