from daq.cli.shutdown import biafc

raise SystemExit(biafc())
