"""``python -m microsim.app.view SCENE [options]`` (same options as ``microsim view``)."""

import sys

from .command import main

if __name__ == "__main__":
    sys.exit(main())
