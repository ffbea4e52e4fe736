import sys

from twinkit.cli import main

sys.exit(main())
