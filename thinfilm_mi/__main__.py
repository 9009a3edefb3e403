"""``python -m thinfilm_mi``: the tool commands (:mod:`thinfilm_mi.cli.tools`)."""
import sys

from thinfilm_mi.cli.tools import main

__all__: list[str] = []   # a script: nothing here to import

if __name__ == "__main__":
    sys.exit(main())
