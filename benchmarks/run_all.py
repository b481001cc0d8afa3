"""Run every benchmark and write the tables to bench-out/ (``make bench``)."""

import io
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import bench_cost  # noqa: E402
import bench_identify  # noqa: E402
import bench_jade  # noqa: E402
import bench_kernel  # noqa: E402
import bench_model_auto  # noqa: E402
import bench_nonlinear  # noqa: E402
import bench_powertrain  # noqa: E402
import bench_search  # noqa: E402
import bench_study  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


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


def weights_study(out=sys.stdout):
    """Fixed vs adaptive track weights: the study file examples/studies/weights.toml (about 5 minutes)."""
    import rideid
    res = rideid.study(ROOT / "examples" / "studies" / "weights.toml", Path("bench-out") / "weights-study")
    out.write((Path("bench-out") / "weights-study" / "summary.md").read_text())
    return res


def main():
    out = Path("bench-out")
    out.mkdir(exist_ok=True)
    for name, mod, kw in (("kernel", bench_kernel, {}), ("nonlinear", bench_nonlinear, {}),
                          ("powertrain", bench_powertrain, {}), ("cost", bench_cost, {}),
                          ("identify", bench_identify, {}), ("jade", bench_jade, {}),
                          ("model_auto", bench_model_auto, {}), ("search", bench_search, {}),
                          ("study", bench_study, {"argv": []})):
        with open(out / f"{name}.md", "w") as f:
            mod.main(out=Tee(sys.stdout, f), **kw)
        print()
    with open(out / "weights.md", "w") as f:
        weights_study(out=Tee(sys.stdout, f))


if __name__ == "__main__":
    main()
