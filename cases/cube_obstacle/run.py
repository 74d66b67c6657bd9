"""Run the cube obstacle benchmark (problem.toml; outputs in results/).

    .venv/bin/python cases/cube_obstacle/run.py              # levels 2 to 5
    .venv/bin/python cases/cube_obstacle/run.py --levels 2 3 # some of them
"""

import sys
from pathlib import Path

from nonsmooth.obstacle_case import main

if __name__ == "__main__":
    sys.exit(main(Path(__file__).resolve().parent, sys.argv[1:]))
