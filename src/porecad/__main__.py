"""``python -m porecad``."""

import sys

from .entry import main

sys.exit(main())
