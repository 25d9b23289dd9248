"""``python -m flexsheet`` is the ``flexsheet`` command."""

import sys

from flexsheet.cli import main

sys.exit(main())
