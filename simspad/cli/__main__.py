"""``python -m simspad.cli``: the same as the ``simspad`` command."""

import sys

from simspad.cli.app import main

sys.exit(main())
