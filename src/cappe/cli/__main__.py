"""``python -m cappe.cli``: the ``cappe`` command."""

import sys

from cappe.cli import main

sys.exit(main())
