import signal
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for path in (ROOT,):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

# A suite started from a background job (`make test &`, nohup) inherits SIGINT ignored, and so do
# the commands its tests start (an ignored signal stays ignored across exec): the interrupt tests
# would see no interrupt. The suite runs as from a terminal, with Python's own SIGINT handler,
# which the commands it starts reset to the default action on exec.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
