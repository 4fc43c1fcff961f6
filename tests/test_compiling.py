"""Brian2's cython modules of one network compile side by side (``neurons.compiling_side_by_side``):
each in a forked child, into Brian2's disk cache, and the run gives what Brian2's own
in-process compile gives."""
import json
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent("""
    import json, os, sys
    import brian2 as b2
    from brian2.codegen.runtime.cython_rt import extension_manager
    from snn_antenna.networks.neurons import compiling_side_by_side

    b2.prefs.codegen.runtime.cython.cache_dir = sys.argv[1]
    cythonize = extension_manager.Cython_Build.cythonize

    def noted(*args, **kwargs):          # which process turned each module into C++
        with open(os.path.join(sys.argv[1], "pids"), "a") as f:
            f.write(f"{os.getpid()}\\n")
        return cythonize(*args, **kwargs)

    extension_manager.Cython_Build.cythonize = noted

    def run(target, side_by_side):
        b2.start_scope()
        b2.prefs.codegen.target = target
        rising = b2.NeuronGroup(3, "dv/dt = (1 + i) / (5 * ms) : 1", name="rising")
        falling = b2.NeuronGroup(3, "dw/dt = -w / (7 * ms) : 1", name="falling")
        falling.w = 1.0
        net = b2.Network(rising, falling)
        if side_by_side:
            with compiling_side_by_side():
                net.run(2 * b2.ms)
        else:
            net.run(2 * b2.ms)
        return [float(x) for x in (*rising.v[:], *falling.w[:])]

    here = run("numpy", False)
    there = run("cython", True)
    print(json.dumps({"pid": str(os.getpid()), "here": here, "there": there}))
""")


def test_each_module_compiles_in_a_child_and_runs_as_brian2s_own(tmp_path):
    done = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path)], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    seen = json.loads(done.stdout.splitlines()[-1])
    compiled_by = (tmp_path / "pids").read_text().split()
    # two state updates, each compiled once, in two children, none in the process that runs
    assert len(compiled_by) == 2 and len(set(compiled_by)) == 2 and seen["pid"] not in compiled_by
    assert len(list(tmp_path.glob("*.so"))) == 2
    assert len(seen["there"]) == 6 and seen["there"][2] > seen["there"][0] > 0
    assert all(abs(a - b) < 1e-9 for a, b in zip(seen["here"], seen["there"]))
