"""``python -m tfbus.cli``: the ``tfbus`` command."""

import sys

from tfbus.cli import main

sys.exit(main())
