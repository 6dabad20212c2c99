"""What the footstep server and live-drive tests share (tests/conftest.py's footstep_server, ONE_WORKER): the
small map every one of them uses, so the programs compiled for it in one file serve the others (one xdist
worker runs them all), and the shared server's limits."""

SHAPE, RES = (40, 32), 0.05  # cells, m: a 2 m x 1.6 m map
WARM_UP = f"{SHAPE[0]}x{SHAPE[1]}@{RES}"  # ijoy serve --warm-up: compiled before it listens
MAX_CELLS, MAX_MAPS = 4096, 4  # the shared server's --max-cells and --max-maps
