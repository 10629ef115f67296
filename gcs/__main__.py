"""`python -m gcs`: the same as the `gcs` console script."""

import sys

from gcs.cli import main

sys.exit(main())
