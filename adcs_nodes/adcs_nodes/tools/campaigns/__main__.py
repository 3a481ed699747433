"""``python -m adcs_nodes.tools.campaigns``: the campaign command, or one run's process."""
# run the package's function, not a copy in __main__, so Dask pickles execute_run by reference
from adcs_nodes.tools.campaigns.cli import main

raise SystemExit(main())
