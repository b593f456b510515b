import sys

from wingopt.cli import main

sys.exit(main())
