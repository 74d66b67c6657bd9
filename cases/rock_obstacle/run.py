"""Run the rock obstacle case (problem.toml; outputs in results/).

    .venv/bin/python cases/rock_obstacle/run.py
"""

import sys
from pathlib import Path

from nonsmooth.obstacle_case import main

if __name__ == "__main__":
    sys.exit(main(Path(__file__).resolve().parent, sys.argv[1:]))
