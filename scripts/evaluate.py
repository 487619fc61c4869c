#!/usr/bin/env python
"""The baseline evaluation: ``dgpt-evaluate`` run from a source tree. Options: ``--help``; the code is
:mod:`dgpt_gym.benchmark.cli`."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dgpt_gym.benchmark.cli import main  # noqa: E402

if __name__ == "__main__":
    raise SystemExit(main())
