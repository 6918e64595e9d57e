"""`python -m fabricfem.cli ...`: the console script `fabricfem` (fabricfem.cli.main)."""
import sys

from fabricfem.cli import main

sys.exit(main())
