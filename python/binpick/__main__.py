"""``python -m binpick``: the ``binpick`` command (:func:`binpick.cli.main`)."""

import sys

from .cli import main

sys.exit(main())
