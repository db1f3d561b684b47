from rosnet_tui.cli import main

raise SystemExit(main())
