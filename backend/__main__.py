"""``python -m backend`` is the ``acs-twin`` command."""

import sys

from backend.cli import main

sys.exit(main())
