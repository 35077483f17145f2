#!/usr/bin/python3
"""Runs across simulated nodes: two network namespaces with their own hostnames, joined by a veth
pair, with Open MPI over TCP between them (its rsh launcher started through `ip netns exec`).

Usage: nodes_test.py BUILD_DIR SOURCE_DIR TEST_NAME (see harness.py).
Open MPI places ranks by hostname, so the ranks of the second namespace are on another node to it:
shared memory only within a node, TCP between. The addresses exist only inside the namespaces the
test makes; nothing is sent elsewhere. Waits are for observable states, with timeouts as bounds.
"""

import contextlib

from harness import *  # noqa: F401,F403 (BUILD, SRC, EXE, MPI_ENV, TMP, run, datasets, many_tiles_job, ...)

SUBNET = "10.77.0"


@contextlib.contextmanager
def two_nodes(local_folder=None):
    """Yields the two namespaces' names (also their hostnames) and an mpirun command prefix that
    starts in the first and places ranks on both; removes namespaces, links and host files after.
    With `local_folder`, the second node sees an empty file system of its own there (a tmpfs in
    its own mount namespace), as a node sees its local scratch."""
    tag = str(os.getpid())
    names = [f"mbn{tag}a", f"mbn{tag}b"]
    links = [f"mbv{tag}a", f"mbv{tag}b"]

    def ip(*args):
        subprocess.run(["ip", *args], check=True, capture_output=True, timeout=30)

    agent = os.path.join(TMP, "node-agent")
    with open(agent, "w") as f:
        # Open MPI calls its rsh agent as `agent HOST COMMAND…`, like ssh: the command runs on the
        # node (the namespace named HOST) under that hostname.
        local = f"mount -t tmpfs node-local {local_folder}; " if local_folder else ""
        f.write('#!/bin/sh\nhost="$1"\nshift\n'
                f'exec ip netns exec "$host" unshare --uts --mount sh -c "{local}hostname $host; $*"\n')
    os.chmod(agent, 0o755)
    try:
        for n in names:
            ip("netns", "add", n)
        ip("link", "add", links[0], "type", "veth", "peer", "name", links[1])
        for i, (n, link) in enumerate(zip(names, links)):
            ip("link", "set", link, "netns", n)
            ip("-n", n, "addr", "add", f"{SUBNET}.{i + 1}/24", "dev", link)
            ip("-n", n, "link", "set", "lo", "up")
            ip("-n", n, "link", "set", link, "up")
            # `ip netns exec` mounts /etc/netns/NAME/hosts over /etc/hosts: each node resolves both.
            os.makedirs(f"/etc/netns/{n}", exist_ok=True)
            with open(f"/etc/netns/{n}/hosts", "w") as f:
                f.write("127.0.0.1 localhost\n" + "".join(f"{SUBNET}.{j + 1} {m}\n" for j, m in enumerate(names)))
        mpirun = ["ip", "netns", "exec", names[0], "unshare", "--uts", "sh", "-c",
                  f'hostname {names[0]}; exec "$0" "$@"', shutil.which("mpirun"),
                  "--mca", "plm_rsh_agent", agent, "--mca", "btl", "self,vader,tcp",
                  "--mca", "btl_tcp_if_include", f"{SUBNET}.0/24", "--mca", "oob_tcp_if_include", f"{SUBNET}.0/24",
                  "--oversubscribe", "-np", "4", "--host", f"{names[0]}:2,{names[1]}:2"]
        yield names, mpirun
    finally:
        for n in names:
            subprocess.run(["ip", "netns", "del", n], capture_output=True, timeout=30)
            shutil.rmtree(f"/etc/netns/{n}", ignore_errors=True)


def netns_pids(name):
    p = subprocess.run(["ip", "netns", "pids", name], capture_output=True, text=True, timeout=30)
    return [int(x) for x in p.stdout.split()]


def ranks_in(name):
    """PIDs of the microbsdf ranks running in namespace `name`."""
    pids = []
    for pid in netns_pids(name):
        try:
            if open(f"/proc/{pid}/comm").read().strip() == "microbsdf":
                pids.append(pid)
        except OSError:
            pass
    return pids


def start_on_nodes(mpirun, args):
    return subprocess.Popen(mpirun + [EXE] + args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=MPI_ENV, cwd=TMP, start_new_session=True)


def test_two_nodes():
    """Four ranks on two nodes write the datasets a one-node run writes, byte for byte, and the
    second node's ranks did compute (their process is seen in its namespace while the run lasts)."""
    job = many_tiles_job(os.path.join(TMP, "job.toml"), 12, "out.h5", paths=40000)
    run(["run", job, "-o", "ref.h5"], mpi=2)
    with two_nodes() as (names, mpirun):
        p = start_on_nodes(mpirun, ["run", job, "-o", "out.h5"])
        seen = set()
        while p.poll() is None:
            seen.update(ranks_in(names[1]))
            time.sleep(0.02)
        out = p.stdout.read()
        assert p.returncode == 0, f"exit {p.returncode}:\n{out}"
        assert "on 4 ranks" in out, out
        assert "not shared" not in out and "does not carry its lock" not in out, out
    assert len(seen) == 2, f"ranks seen on the second node: {sorted(seen)}"
    assert datasets(os.path.join(TMP, "out.h5")) == datasets(os.path.join(TMP, "ref.h5")), "the two-node table differs"
    print("4 ranks on 2 nodes (2 of them seen on the second): datasets identical to one node's")


def test_node_local_output():
    """An output folder the second node does not share (its own empty file system there): the run
    computes the table on rank 0's node and says, at its start and in its closing summary, which
    ranks and node do not see the output's lock file and what follows. A shared folder whose lock
    every node sees held raises nothing (test_two_nodes runs one)."""
    local = os.path.join(TMP, "local")
    os.makedirs(local, exist_ok=True)
    job = many_tiles_job(os.path.join(TMP, "job.toml"), 2, "out.h5", paths=20000)
    out_h5 = os.path.join(local, "out.h5")
    with two_nodes(local) as (names, mpirun):
        p = start_on_nodes(mpirun, ["run", job, "-o", out_h5])
        out, _ = p.communicate(timeout=600)
    assert p.returncode == 0, f"exit {p.returncode}:\n{out}"
    said = f"the output folder is not shared with 2 ranks on {names[1]} (they do not see {out_h5}.lock"
    warned = [line for line in out.splitlines() if said in line]
    assert len(warned) == 2 and all("[warning]" in line for line in warned), out
    assert "does not carry its lock" not in out, out
    assert os.path.exists(out_h5), "no table on rank 0's node"
    print(f"node-local output: warned twice ({warned[0].split('] ', 1)[-1][:90]}…)")


def test_node_lost():
    """The second node lost in mid-run (every process of its namespace killed, as a power cut would):
    the run ends with a non-zero exit that the README's table lists, the slices journaled before stay
    in the partial file, and --resume on the node that remains completes a table identical to a clean
    run. The run is frozen (SIGSTOP) before the kill, so the loss falls in mid-run whatever the speed."""
    job = many_tiles_job(os.path.join(TMP, "job.toml"), 12, "out.h5", paths=200000)
    run(["run", job, "-o", "ref.h5"], mpi=2)
    out_h5 = os.path.join(TMP, "out.h5")
    with two_nodes() as (names, mpirun):
        p = start_on_nodes(mpirun, ["run", job, "-o", "out.h5"])
        t0 = time.time()
        while journal_count(out_h5) < 2 or len(ranks_in(names[1])) < 2:
            assert p.poll() is None, "the run ended before the node was lost:\n" + p.stdout.read()
            assert time.time() - t0 < 300, "no slice finished"
            time.sleep(0.02)
        os.killpg(p.pid, signal.SIGSTOP)
        assert not os.path.exists(out_h5), "the run finished before it was frozen"
        for pid in netns_pids(names[1]):
            os.kill(pid, signal.SIGKILL)
        os.killpg(p.pid, signal.SIGCONT)
        try:
            out, _ = p.communicate(timeout=600)
        finally:
            subprocess.run(["pkill", "-KILL", "-s", str(p.pid)])
            wait_session_gone(p.pid)
    readme = open(os.path.join(SRC, "README.md")).read()
    cells = re.findall(r"^\| ([^|]*) \|", readme[readme.index("## Exit codes"):], re.M)
    documented = {int(c) for cell in cells for c in re.findall(r"`(\d+)`", cell)}
    assert p.returncode != 0, f"exit 0 after a node was lost:\n{out}"
    assert p.returncode in documented or p.returncode > 128, f"exit {p.returncode} is not in the README's table:\n{out}"
    kept = journal_count(out_h5)
    assert kept >= 2, f"{kept} slices journaled"
    resumed = run(["run", job, "-o", "out.h5", "--resume"], mpi=2)
    text = resumed.stdout + resumed.stderr
    assert f"resuming: {kept} of 48 slices" in text, text
    assert datasets(out_h5) == datasets(os.path.join(TMP, "ref.h5")), "the resumed table differs"
    print(f"second node lost: exit {p.returncode}; {kept} of 48 slices kept, --resume on one node identical")


if __name__ == "__main__":
    run_selected(globals())
