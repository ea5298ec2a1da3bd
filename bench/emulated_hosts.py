"""The figures of bench/emulated_hosts.sh, from what one point leaves behind.

  emulated_hosts.py point PDIR W R LAT_MS GBIT FRAMES IDENTICAL ROUND ROWS
      reads PDIR/turn.json (the turntable job's statistics: docs/formats.md,
      "Cluster frame statistics") and PDIR/warm.json (the warm-up job's), the display's /metrics and every relay's
      byte counts scraped before and after that job, prints the point's row
      and appends it as one JSON object to ROWS. Exit status 1 when a frame
      is not bit-identical to the in-process render.
  emulated_hosts.py header
      the column names of the rows.
  emulated_hosts.py summary ROWS [JSON]
      the medians over rounds of each point's time figures (the counts of
      rays and bytes are the same in every round, else the exit status is 1),
      as a table and, with JSON, one object per point in that file.

The columns and the JSON fields are described in bench/README.md, "Emulated
hosts".
"""
import json
import statistics
import sys

HEADER = (f"{'W':>2} {'R':>2} {'lat_ms':>6} {'Gbit':>5} {'frame_ms':>9} {'fps':>6} {'idle%':>5} "
          f"{'rays/link/frame':>22} {'wire KB/link/frm':>18} {'hops':>6} {'assem_ms':>9} "
          f"{'tail_ms':>7} {'load_ms':>8}")


def ip(host):
    return f"10.77.0.{host}"


def host_of(address):
    """The host index of an address 10.77.0.H:PORT."""
    return int(address.split(":")[0].split(".")[-1])


def prom(path, name):
    """A series without labels from a scrape, 0 when absent."""
    for line in open(path):
        if line.startswith(name + " "):
            return float(line.split()[1])
    return 0.0


def relay_counts(pdir, prefix, host):
    """The relay of `host`: peer ip -> (bytes in, bytes out)."""
    try:
        text = open(f"{pdir}/{prefix}-relay-{host}.stats").read()
    except FileNotFoundError:
        return {}
    return {f[0]: (int(f[1]), int(f[2])) for f in (l.split() for l in text.splitlines())
            if len(f) == 4}


def point(pdir, w, r, lat, gbit, frames, identical, rnd, rows_path):
    stats = json.load(open(f"{pdir}/turn.json"))
    # The warm-up job's first frame waited for the slabs to go out over the
    # links: its load_ms.
    try:
        load_ms = float(json.load(open(f"{pdir}/warm.json"))[0].get("load_ms", 0))
    except (FileNotFoundError, IndexError, ValueError):
        load_ms = float("nan")
    # R "auto": the root's cluster model chose; the rings it formed.
    auto = r == "auto"
    r = int(stats[0].get("rings", 1)) if auto else int(r)
    n = len(stats)
    frame_ms = [s["frame_ms"] for s in stats]
    workers = [wk for s in stats for wk in s["workers"]]
    count = lambda field: sum(int(wk.get(field, 0)) for wk in workers)
    traced, forwarded = count("rays_traced"), count("rays_sent")
    # Each ring's workers in slab order: link k joins worker k and k + 1,
    # and carries what k sends right and k + 1 sends left.
    by_link = {}
    for s in stats:
        rings = {}
        for wk in s["workers"]:
            rings.setdefault(wk.get("ring", 0), []).append(wk)
        for ring, ws in sorted(rings.items()):
            ws.sort(key=lambda x: x["slab"][0])
            for k in range(len(ws) - 1):
                a, b = ws[k], ws[k + 1]
                e = by_link.setdefault((ring, k), {
                    "link": f"r{ring}:{k}-{k + 1}", "ring": ring, "left": a["address"],
                    "right": b["address"], "rays": 0, "rays_received": 0})
                e["rays"] += int(a.get("sent_right", 0)) + int(b.get("sent_left", 0))
                e["rays_received"] += (int(b.get("received_left", 0)) +
                                       int(a.get("received_right", 0)))
    links = []
    for _, e in sorted(by_link.items()):
        # The left worker opens the stream to the right one, through the
        # right worker's relay, which counts it under the left one's address.
        lhost, rhost = host_of(e["left"]), host_of(e["right"])
        b0 = relay_counts(pdir, "before", rhost).get(ip(lhost), (0, 0))
        b1 = relay_counts(pdir, "after", rhost).get(ip(lhost), (0, 0))
        e["wire_bytes"] = (b1[0] - b0[0]) + (b1[1] - b0[1])
        links.append(e)
    scrape = lambda name: (prom(f"{pdir}/after-display.prom", name) -
                           prom(f"{pdir}/before-display.prom", name))
    assembled = scrape("transtick_display_frame_assembly_seconds_count")
    assembly_ms = (scrape("transtick_display_frame_assembly_seconds_sum") * 1e3 / assembled
                   if assembled else float("nan"))
    start, end = map(float, open(f"{pdir}/wall").read().split())
    distinct = traced - forwarded  # a ray forwarded is traced once more where it arrives
    idle = [1 - wk["active_ms"] / wk["elapsed_ms"] for wk in workers if wk.get("elapsed_ms", 0) > 0]
    row = {
        "workers": w, "rings": r, "auto": auto, "latency_ms": lat, "gbit": gbit, "round": rnd,
        "frames": n, "frames_identical": identical,
        "frame_ms_median": statistics.median(frame_ms), "frame_ms_min": min(frame_ms),
        "frame_ms_mean": statistics.mean(frame_ms), "frames_per_s": n / (end - start),
        "idle_share": statistics.mean(idle) if idle else 0.0,
        "rays_traced": traced, "rays_forwarded": forwarded,
        "hops_per_ray": forwarded / distinct if distinct else 0.0,
        "rays_sent": count("rays_sent"), "ray_bytes_sent": count("bytes_sent"),
        "deposits": count("deposits"), "deposit_bytes": count("deposit_bytes"),
        "assembly_ms_mean": assembly_ms, "tail_ms": statistics.mean(frame_ms) - assembly_ms,
        "load_ms": load_ms,
        # For the cluster model (bench/cluster_model): a frame's summed
        # tracer CPU, slowest over mean active time, and pixels.
        "tracer_cpu_ms": statistics.median(sum(wk.get("cpu_ms", 0) for wk in s["workers"])
                                           for s in stats),
        "active_imbalance": statistics.median(s.get("active_imbalance", 0) for s in stats),
        "pixels": stats[0]["width"] * stats[0]["height"],
        "links": links,
    }
    with open(rows_path, "a") as f:
        f.write(json.dumps(row) + "\n")
    ok = identical == frames == n
    print(format_row(row) + ("" if ok else f"  IMAGES DIFFER: {frames - identical} of {frames}"))
    return 0 if ok else 1


def span(values, scale):
    if not values:
        return "-"
    mean = statistics.mean(values) / scale
    if len(values) == 1:
        return f"{mean:.0f}"
    return f"{mean:.0f} [{min(values) / scale:.0f}-{max(values) / scale:.0f}]"


def format_row(p):
    n = p["frames"]
    rays = [l["rays"] / n for l in p["links"]]
    wire = [l["wire_bytes"] / n for l in p["links"]]
    gbit = f"{p['gbit']:g}" if p["gbit"] > 0 else "-"
    rings = f"a{p['rings']}" if p.get("auto") else p["rings"]
    return (f"{p['workers']:>2} {rings:>2} {p['latency_ms']:>6g} {gbit:>5} "
            f"{p['frame_ms_median']:>9.1f} {p['frames_per_s']:>6.2f} {100 * p['idle_share']:>5.1f} "
            f"{span(rays, 1):>22} {span(wire, 1e3):>18} {p['hops_per_ray']:>6.3f} "
            f"{p['assembly_ms_mean']:>9.1f} {p['tail_ms']:>7.1f} {p.get('load_ms', float('nan')):>8.1f}")


def summary(rows_path, json_path):
    rows = [json.loads(l) for l in open(rows_path)]
    points = {}
    for p in rows:
        key = (p["workers"], p["rings"], p.get("auto", False), p["latency_ms"], p["gbit"])
        points.setdefault(key, []).append(p)
    status = 0
    out = []
    for key, ps in points.items():
        m = dict(ps[0])
        m["rounds"] = len(ps)
        del m["round"]
        for field in ("frame_ms_median", "frame_ms_min", "frame_ms_mean", "frames_per_s",
                      "idle_share", "assembly_ms_mean", "tail_ms", "tracer_cpu_ms",
                      "active_imbalance", "load_ms"):
            m[field] = statistics.median(p[field] for p in ps)
        m["frames_identical"] = min(p["frames_identical"] for p in ps)
        # Balancing is off: the same cuts and the same rays every round.
        counts = {(p["rays_forwarded"], tuple(l["rays"] for l in p["links"])) for p in ps}
        if len(counts) > 1:
            print(f"rays differ between rounds at {key}: {counts}")
            status = 1
        out.append(m)
    if len(rows) > len(points):
        print(f"median of {max(m['rounds'] for m in out)} rounds:")
        print(HEADER)
        for m in out:
            print(format_row(m))
    if json_path:
        with open(json_path, "w") as f:
            for m in out:
                f.write(json.dumps(m) + "\n")
    return status


if __name__ == "__main__":
    a = sys.argv
    if len(a) == 11 and a[1] == "point":
        sys.exit(point(a[2], int(a[3]), a[4], float(a[5]), float(a[6]), int(a[7]), int(a[8]),
                       int(a[9]), a[10]))
    if len(a) == 2 and a[1] == "header":
        sys.exit(print(HEADER))
    if len(a) in (3, 4) and a[1] == "summary":
        sys.exit(summary(a[2], a[3] if len(a) == 4 else ""))
    sys.exit(__doc__)
