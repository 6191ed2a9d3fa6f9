from lipgen.cli import main

raise SystemExit(main())
