"""``python -m flexsheet`` is the ``flexsheet`` command."""

import sys

from .cli import main

sys.exit(main())
