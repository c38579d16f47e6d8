"""``python -m cappe``: the ``cappe`` command."""

import sys

from cappe.cli import main

sys.exit(main())
