"""``python -m flexcal.validation.cli``: the same as the ``flexcal`` command."""

import sys

from . import main

sys.exit(main())
