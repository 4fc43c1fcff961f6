"""Diagnostic (issue 31): NMF-30 material accuracy on the quick bench set, raw vs peak-scaled
spectra, dot-product (basis) vs dual (pinv) filters vs NMF activations, 60 vs 300 epochs.
Usage: python benchmarks/nmf_scaling.py 'run("name", X, scale_peak=True, iters=300)' ...
NB: NMFFilterBank now peak-scales itself, so scale_peak=False reproduces the old numbers only
on the commit before the fix."""
import sys, time, warnings
import numpy as np
from sklearn.decomposition import NMF
from sklearn.neural_network import MLPClassifier
from sklearn.preprocessing import StandardScaler
from sklearn.pipeline import make_pipeline
warnings.filterwarnings("ignore")
from threadpoolctl import threadpool_limits
from snn_antenna import spec as specmod
from snn_antenna.studies import baseline_comparison as bc
from snn_antenna.evaluation import signal, crossval as cv
from snn_antenna.readout.baselines import NMFFilterBank

s = specmod.load("studies/baseline_comparison.toml", quick="--full" not in sys.argv)
sys.argv = [a for a in sys.argv if a != "--full"]
parts = bc.build(s)
parts.bench.cache_dir = "/tmp/i31cache"
data, f = signal.load_features(parts.bench, parts.processor)
f = f.isel(event=np.flatnonzero(f["skipped"].values == ""))
X = f["spectrum"].values.astype(float)
mats = sorted(set(f["material"].values.astype(str)))
y = cv.targets_of(f, "material", mats)
print(X.shape, "amp range of peaks", np.percentile(X.max(1), [5, 50, 95]))

def run(name, Xin, n=30, iters=60, scale_peak=False, transform="dot", seed=0):
    tr, te = cv.split_by_repetition(f["repetition"].values, 0.3, seed)
    Z = Xin / Xin.max(1, keepdims=True) if scale_peak else Xin
    t = time.time()
    if transform == "none":
        F = Z
    else:
        bank = NMFFilterBank(n, 400, random_state=seed).fit(Z[tr])
        W = bank.components_
        F = {"dot": lambda: Z @ W.T, "nmf": lambda: bank.nmf_.transform(Z),
             "dual": lambda: Z @ np.linalg.pinv(W)}[transform]()
    clf = make_pipeline(StandardScaler(), MLPClassifier((51,), max_iter=iters, batch_size=64, random_state=seed))
    clf.fit(F[tr], y[tr])
    print(f"{name:40s} acc {np.mean(clf.predict(F[te]) == y[te]):.3f}  {time.time()-t:.0f}s", flush=True)

with threadpool_limits(1):
    for a in sys.argv[1:]:
        eval(a)
