"""``python -m sns_np``: the same as the ``sns-np`` command."""

import sys

from .cli import main

sys.exit(main())
