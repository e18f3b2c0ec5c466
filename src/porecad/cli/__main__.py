"""``python -m porecad.cli``."""

import sys

from .main import main

sys.exit(main())
