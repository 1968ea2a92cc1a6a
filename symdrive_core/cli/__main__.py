"""``python -m symdrive_core.cli``: the ``symdrive`` command without the installed entry point."""

import sys

from . import main

sys.exit(main())
