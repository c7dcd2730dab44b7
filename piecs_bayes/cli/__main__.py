"""`python -m piecs_bayes.cli ...` is `piecs-bayes ...`."""

import sys

from ._main import main

if __name__ == "__main__":
    sys.exit(main())
