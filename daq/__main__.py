from daq.cli.biafc import main

raise SystemExit(main())
