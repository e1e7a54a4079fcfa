from training.export.cli import main

raise SystemExit(main())
