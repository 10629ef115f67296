"""``python -m vehicles sim ...`` (same as the ``vehicles`` console script)."""

import sys

from vehicles.cli import main

sys.exit(main())
