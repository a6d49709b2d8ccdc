"""``python -m sitl_mock``: same as the ``sitl-mock`` command."""

import sys

from sitl_mock.cli import main

sys.exit(main())
