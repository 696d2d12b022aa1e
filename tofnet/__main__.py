import sys

from tofnet.cli import main

sys.exit(main())
