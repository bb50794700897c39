"""``python -m dftc_mujoco.calibrate``: see :mod:`dftc_mujoco.calibrate`."""

import sys

from .command import main

sys.exit(main())
