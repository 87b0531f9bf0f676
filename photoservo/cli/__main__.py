"""`python -m photoservo.cli VERB ...`: the same as the `photoservo` console script."""

import sys

from photoservo.cli.main import main

sys.exit(main())
