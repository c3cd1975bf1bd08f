"""`python -m fcmaster` runs the command line."""

from fcmaster.cli import main

raise SystemExit(main())
