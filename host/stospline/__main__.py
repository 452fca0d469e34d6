"""``python -m stospline``: the same command line as the ``stospline`` script."""
import sys

from stospline.cli import main

if __name__ == "__main__":
    sys.exit(main())
