import sys

from pf_offboard.cli import main

sys.exit(main())
