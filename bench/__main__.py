import sys

from bench.run import main

if __name__ == "__main__":  # multiprocessing (spawn) re-imports this module as __mp_main__
    sys.exit(main())
