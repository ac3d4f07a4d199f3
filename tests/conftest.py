import sys
from pathlib import Path

# test helpers (signals.py) importable from every test module
sys.path.insert(0, str(Path(__file__).parent))
