"""Run every benchmark and write the tables to bench-out/ (``make bench``)."""

import io
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import bench_cost  # noqa: E402
import bench_identify  # noqa: E402
import bench_jade  # noqa: E402
import bench_model_auto  # noqa: E402
import study_weights  # noqa: E402


class Tee(io.TextIOBase):
    def __init__(self, *streams):
        self.streams = streams

    def write(self, s):
        for st in self.streams:
            st.write(s)
        return len(s)

    def flush(self):
        for st in self.streams:
            st.flush()


def main():
    out = Path("bench-out")
    out.mkdir(exist_ok=True)
    for name, mod, kw in (("cost", bench_cost, {}), ("identify", bench_identify, {}), ("jade", bench_jade, {}),
                          ("weights", study_weights, {"argv": []})):
        with open(out / f"{name}.md", "w") as f:
            mod.main(out=Tee(sys.stdout, f), **kw)
        print()


if __name__ == "__main__":
    main()
