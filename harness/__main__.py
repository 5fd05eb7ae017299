"""``python -m harness`` is the same as the ``gpis-harness`` command."""

import sys

from harness.cli import main

sys.exit(main())
