"""``python -m crowdnav``: the same as the ``crowdnav`` command."""

import sys

from crowdnav.cli import main

sys.exit(main())
