"""A lab's antenna that is not this project's, recorded by the lab's own equipment: the files a
lab would bring to ``snn-antenna data import``, written here without the package's physics.

The rod rings in two damped modes after each contact. Its first mode FALLS with the contact's
distance from the base, 60 Hz at 10 cm to 12 Hz at 34 cm (geometrically); its second sits at
``HIGH_RATIO`` times the first. A material changes nothing but the decay time (``DECAY_S``),
and the lab's set holds a material the paper never used (``rubber``). The ringing lies in a
plane at ``PLANE_RAD`` between the x and y axes; z carries gravity.
"""
from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

GRAVITY = 9.80665
DECAY_S = {"rubber": 0.03, "wood": 0.06, "pom": 0.11, "aluminium": 0.22}
NEAR_CM, FAR_CM = 10.0, 34.0
NEAR_HZ, FAR_HZ = 60.0, 12.0
HIGH_RATIO = 3.7
PLANE_RAD = 0.6
# another lab's rod, its constants chosen apart from the read-outs' fitted rules (a rod they
# were not fitted on): five materials, a first
# mode from 75 Hz at 10 cm to 15 Hz at 34 cm, its second at 3.1 times it (``session``'s keys)
OTHER_ROD = {"decay_s": {"felt": 0.025, "rubber": 0.045, "wood": 0.08, "pom": 0.14,
                         "aluminium": 0.28},
             "law_hz": (75.0, 15.0), "high_ratio": 3.1}
AMPLITUDE_G = 3.0
NOISE_G = 0.01


def low_hz(distance_cm, law_hz=(NEAR_HZ, FAR_HZ)):
    """The lab rod's first mode: ``law_hz`` = (at 10 cm, at 34 cm), 60 Hz falling to 12 Hz
    unless another rod's is given, geometric between them."""
    x = (np.asarray(distance_cm, dtype=float) - NEAR_CM) / (FAR_CM - NEAR_CM)
    near, far = law_hz
    return near * (far / near) ** x


@dataclass(frozen=True)
class Contact:
    t_s: float              # from the session's first sample
    distance_cm: float
    material: str
    repetition: int


@dataclass
class Session:
    """A recorded session: accelerations (samples, 3) in g at ``rate_hz``, and its contacts."""
    g: np.ndarray
    rate_hz: float
    contacts: list[Contact]

    @property
    def duration_s(self) -> float:
        return len(self.g) / self.rate_hz


def session(rate_hz: float, materials=("rubber", "wood", "aluminium"),
            distances_cm=(10.0, 18.0, 26.0, 34.0), repetitions: int = 2, seed: int = 0,
            spacing_s: float = 1.3, lead_s: float = 0.8, decay_s=None,
            law_hz=(NEAR_HZ, FAR_HZ), high_ratio: float = HIGH_RATIO) -> Session:
    """Every (material, distance) struck ``repetitions`` times in a shuffled order, one
    contact every ``spacing_s`` (± 0.1 s). Another lab's rod: its materials' decay times
    ``decay_s`` (default ``DECAY_S``), its first mode's ``law_hz`` (``low_hz``) and its
    second mode's ``high_ratio``."""
    decay_s = DECAY_S if decay_s is None else decay_s
    rng = np.random.default_rng(seed)
    sites = [(m, d, r) for r in range(repetitions) for m in materials for d in distances_cm]
    order = rng.permutation(len(sites))
    onsets = lead_s + spacing_s * np.arange(len(sites)) + rng.uniform(-0.1, 0.1, len(sites))
    n = int(round((onsets[-1] + spacing_s) * rate_hz))
    t = np.arange(n) / rate_hz
    ring = np.zeros(n)
    contacts = []
    for onset, k in zip(onsets, order):
        material, d, rep = sites[k]
        start = int(np.ceil(onset * rate_hz))
        s = t[start:] - onset
        tau, f1 = decay_s[material], float(low_hz(d, law_hz))
        phase = rng.uniform(-0.3, 0.3)
        ring[start:] += AMPLITUDE_G * (np.exp(-s / tau) * np.sin(2 * np.pi * f1 * s + phase)
                                       + 0.5 * np.exp(-2 * s / tau)
                                       * np.sin(2 * np.pi * high_ratio * f1 * s))
        contacts.append(Contact(float(onset), d, material, rep))
    noise = rng.standard_normal((n, 3)) * NOISE_G
    g = np.column_stack([ring * np.cos(PLANE_RAD), ring * np.sin(PLANE_RAD), np.ones(n)]) + noise
    return Session(g, rate_hz, contacts)


def labels_csv(path: Path, sess: Session, recording: str, origin_s: float = 0.0,
               lag_s: float = 0.0) -> Path:
    """The lab's labels table: each contact's time on the recording's clock (its first sample
    at ``origin_s``), written ``lag_s`` late."""
    lines = ["recording,onset_s,distance_cm,material,repetition"]
    lines += [f"{recording},{origin_s + c.t_s + lag_s:.6f},{c.distance_cm:g},{c.material},"
              f"{c.repetition}" for c in sess.contacts]
    path.write_text("\n".join(lines) + "\n")
    return path


def spreadsheet_csv(path: Path, sess: Session, origin_s: float) -> Path:
    """What a spreadsheet in a decimal-comma locale saves: a byte-order mark, ``;`` between
    fields, decimal commas, its own column names, time from ``origin_s``, accelerations in g."""
    with open(path, "w", encoding="utf-8-sig", newline="") as f:
        f.write("time;ax;ay;az\r\n")
        t = origin_s + np.arange(len(sess.g)) / sess.rate_hz
        for ti, (x, y, z) in zip(t, sess.g):
            f.write(f"{ti:.6f};{x:.5f};{y:.5f};{z:.5f}\r\n".replace(".", ","))
    return path


def counts_csv(path: Path, counts: np.ndarray, rate_hz: float, origin_s: float) -> Path:
    """Plain CSV of ADC counts with its time column from ``origin_s``."""
    t = origin_s + np.arange(len(counts)) / rate_hz
    path.write_text("t_s,x,y\n" + "".join(f"{ti:.6f},{x},{y}\n"
                                          for ti, (x, y) in zip(t, counts)))
    return path


def adc_counts(g: np.ndarray, bits: int, full_scale_g: float) -> np.ndarray:
    """Unsigned counts of an ADC of ``bits`` over ± ``full_scale_g``, clipped at its rails."""
    levels = 2 ** bits
    return np.clip(np.round(levels / 2 + g * levels / (2 * full_scale_g)), 0,
                   levels - 1).astype(np.int64)


def narrow_wav(path: Path, sess: Session, bits: int = 12, full_scale_g: float = 16.0) -> Path:
    """x and y through a ``bits``-bit ADC, left-justified in 16-bit PCM (the low bits 0), as
    a 16-bit recorder stores a narrower converter."""
    from scipy.io import wavfile

    counts = adc_counts(sess.g[:, :2], bits, full_scale_g)
    pcm = ((counts - 2 ** (bits - 1)) << (16 - bits)).astype(np.int16)
    wavfile.write(path, int(sess.rate_hz), pcm)
    return path


def _imu_template():
    """One Imu message serialised by rosbags, with where its stamp and acceleration sit."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    t = store.types
    zeros = np.zeros(9)
    marks = (1234.5, 2345.5, 3456.5)
    msg = t["sensor_msgs/msg/Imu"](
        header=t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](
            sec=0x1234567, nanosec=0x7654321), frame_id="lab_imu"),
        orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=zeros,
        angular_velocity=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
        angular_velocity_covariance=zeros,
        linear_acceleration=t["geometry_msgs/msg/Vector3"](x=marks[0], y=marks[1], z=marks[2]),
        linear_acceleration_covariance=zeros)
    raw = bytes(store.serialize_cdr(msg, "sensor_msgs/msg/Imu"))
    stamp = raw.index(struct.pack("<iI", 0x1234567, 0x7654321))
    accel = raw.index(struct.pack("<ddd", *marks))
    return store, raw, stamp, accel


def imu_bag(path: Path, sess: Session, first_stamp_ns: int, jitter_ns: int = 0,
            drop=(), storage: str = "sqlite3", seed: int = 0) -> list[int]:
    """A ROS 2 bag of one ``/lab/imu`` Imu topic: the accelerations in m/s², each message
    stamped on the lab computer's clock (``first_stamp_ns`` + its instant, ± ``jitter_ns``),
    the messages at indexes ``drop`` lost. Returns the stamps written."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    store, template, at_stamp, at_accel = _imu_template()
    rng = np.random.default_rng(seed)
    period = 1e9 / sess.rate_hz
    jitter = rng.integers(-jitter_ns, jitter_ns + 1, len(sess.g)) if jitter_ns else \
        np.zeros(len(sess.g), np.int64)
    dropped = set(int(i) for i in drop)
    stamps = []
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=8, storage_plugin=plugin) as writer:
        connection = writer.add_connection("/lab/imu", "sensor_msgs/msg/Imu", typestore=store)
        buf = bytearray(template)
        for i, (x, y, z) in enumerate(sess.g * GRAVITY):
            if i in dropped:
                continue
            ns = first_stamp_ns + int(round(i * period)) + int(jitter[i])
            struct.pack_into("<iI", buf, at_stamp, ns // 10**9, ns % 10**9)
            struct.pack_into("<ddd", buf, at_accel, x, y, z)
            writer.write(connection, ns, bytes(buf))
            stamps.append(ns)
    return stamps


def decay_time_s(g_xy: np.ndarray, rate_hz: float, pre_s: float) -> float:
    """A one-feature read-out: the time from the onset until the ringing's upper envelope
    (the largest deflection still to come) falls to 1/e of its peak (the lab's materials
    differ in nothing else)."""
    r = np.hypot(g_xy[:, 0] - np.median(g_xy[:, 0]), g_xy[:, 1] - np.median(g_xy[:, 1]))
    r = r[int(round(pre_s * rate_hz)):]
    envelope = np.maximum.accumulate(r[::-1])[::-1]
    below = np.flatnonzero(envelope < envelope[0] / np.e)
    return below[0] / rate_hz if len(below) else len(r) / rate_hz


def peak_hz(g_xy: np.ndarray, rate_hz: float, pre_s: float, min_hz: float = 5.0) -> float:
    """A one-feature read-out of the first mode: the frequency of the largest bin of the
    ringing's amplitude spectrum (x and y projected on their main direction), above
    ``min_hz``, zero-padded to 0.25 Hz bins."""
    xy = g_xy[int(round(pre_s * rate_hz)):] - np.median(g_xy, axis=0)
    main = np.linalg.svd(xy - xy.mean(axis=0), full_matrices=False)[2][0]
    x = (xy - xy.mean(axis=0)) @ main
    n = max(len(x), int(4 * rate_hz))
    amplitude = np.abs(np.fft.rfft(x, n))
    f = np.fft.rfftfreq(n, 1.0 / rate_hz)
    above = f >= min_hz
    return float(f[above][np.argmax(amplitude[above])])


def one_feature_readouts(g: np.ndarray, rate_hz: float, pre_s: float, material, distance,
                         train, test) -> tuple[float, float]:
    """(material accuracy of the decay time, distance rmse in mm of the peak frequency), each
    set on the ``train`` contacts and read on the ``test`` ones: the material by thresholds
    between neighbouring materials' median decay times (geometric middles), the distance by a
    line through log10 of the peak frequency."""
    tau = np.asarray([decay_time_s(ev, rate_hz, pre_s) for ev in g])
    material = np.asarray(material).astype(str)
    names = sorted(set(material[train]), key=lambda m: np.median(tau[train & (material == m)]))
    medians = [np.median(tau[train & (material == m)]) for m in names]
    edges = np.sqrt(np.multiply(medians[1:], medians[:-1]))
    read = np.asarray(names)[np.searchsorted(edges, tau[test])]
    accuracy = float(np.mean(read == material[test]))
    logf = np.log10([peak_hz(ev, rate_hz, pre_s) for ev in g])
    distance = np.asarray(distance, dtype=float)
    slope, intercept = np.polyfit(logf[train], distance[train], 1)
    rmse_mm = 10 * float(np.sqrt(np.mean((slope * logf[test] + intercept - distance[test]) ** 2)))
    return accuracy, rmse_mm


def against_one_feature(run: Path, source) -> dict:
    """Per read-out of a comparison's ``predictions.json``: (its mean score over the splits,
    the one-feature read-out's mean score on the same training and test contacts, the task):
    accuracy against the decay time's, rmse (mm) against the peak frequency's."""
    ds = source.dataset
    g = ((ds["counts"].values.astype(float) - 2 ** (source.adc_bits - 1))
         * 2 * source.full_scale_g / 2 ** source.adc_bits)
    predictions = json.loads((run / "predictions.json").read_text())
    events = ds["event"].values
    cache, out = {}, {}
    for name, folds in predictions["folds"].items():
        task = predictions["task"][name]
        if task not in ("material", "distance"):
            continue
        mine, reference = [], []
        for fold in folds:
            key = (tuple(fold["train_event"]), tuple(fold["test_event"]))
            if key not in cache:
                cache[key] = one_feature_readouts(
                    g, source.rate_hz, source.pre_trigger_s, ds["material"].values,
                    ds["distance_cm"].values, np.isin(events, fold["train_event"]),
                    np.isin(events, fold["test_event"]))
            true, said = np.asarray(fold["true"]), np.asarray(fold["predicted"])
            if task == "material":
                mine.append(np.mean(true == said))
                reference.append(cache[key][0])
            else:
                mine.append(10 * np.sqrt(np.mean((true - said) ** 2)))
                reference.append(cache[key][1])
        out[name] = (float(np.mean(mine)), float(np.mean(reference)), task)
    return out
