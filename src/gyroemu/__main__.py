"""``python -m gyroemu``: the command line, as the ``gyroemu`` console script runs it."""

from gyroemu.pipelines.cli import main

raise SystemExit(main())
