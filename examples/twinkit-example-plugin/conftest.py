# Lets the example's tests import it from the source tree (a real user would `pip install -e .` first).
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
