"""``python -m twinkit`` = the ``twinkit`` command."""
import sys

from twinkit.cli import main

if __name__ == "__main__":
    sys.exit(main())
