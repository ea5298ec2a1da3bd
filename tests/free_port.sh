# Sourced by the shell tests. port: a free TCP port on 127.0.0.1 for a
# daemon that must listen on a port known in advance (and keep it across
# restarts). It is drawn below the kernel's ephemeral range, so that neither
# a daemon of a test running beside this one that listens on port 0 nor an
# outgoing connection can take it between the draw and the daemon's bind.
port() {
  python3 - <<'PY'
import random, socket
try:
    low = int(open("/proc/sys/net/ipv4/ip_local_port_range").read().split()[0])
except (OSError, ValueError, IndexError):
    low = 32768
for _ in range(1000):
    p = random.randrange(10000, max(low, 10001))
    s = socket.socket()
    try:
        s.bind(("127.0.0.1", p))
    except OSError:
        continue
    finally:
        s.close()
    print(p)
    break
else:
    raise SystemExit("free_port: no free port below the ephemeral range")
PY
}
