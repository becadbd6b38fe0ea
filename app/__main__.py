import sys

from railval.app.cli import main

sys.exit(main())
