import sys

from wingopt._console import main

sys.exit(main())
