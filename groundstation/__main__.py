from .core.blas_threads import one_blas_thread

one_blas_thread()                 # before numpy loads: see core/blas_threads.py

from .cli.main import main  # noqa: E402

raise SystemExit(main())
