"""`python -m rta_attitude.cli ...`: the same as the `rta-attitude` console script."""

import sys

from rta_attitude.cli.main import main

sys.exit(main())
