"""``python -m cvpipe``: the ``cvpipe`` program (see :mod:`cvpipe._entry`)."""

import sys

from cvpipe._entry import main

if __name__ == "__main__":
    sys.exit(main())
