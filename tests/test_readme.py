"""The README's Python example runs as printed (a moved module would break it silently)."""
import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_the_python_example_in_the_readme_runs():
    text = README.read_text()
    section = text[text.index("## Using the pieces from Python"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    namespace: dict = {}
    exec(compile(code, "README.md", "exec"), namespace)
    rates = namespace["rates"]
    assert rates.sizes["neuron_hz"] == 24 and float(rates.sum()) > 0
