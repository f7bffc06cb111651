"""``python -m leosop``: the command line (:func:`leosop.cli.main_exit`)."""

try:
    from .cli import main_exit
except KeyboardInterrupt:  # Ctrl-C while numpy loads: one line, as within a command
    import sys

    print("leosop: interrupted", file=sys.stderr)
    sys.exit(1)

main_exit()
