"""Real servers for the cluster tests, started in a temporary folder and stopped afterwards.

* :func:`slurm_cluster`: a one-node SLURM cluster on this machine (munged, MariaDB for the
  accounting database, slurmdbd, slurmctld, slurmd), so ``sbatch``, ``squeue``, ``scancel``
  and ``sacct`` (which submitit polls) all work as on a real cluster.
* :func:`postgres_database`: a throwaway PostgreSQL server and database; yields its SQLAlchemy URL.

Every process started here carries the environment variable ``HERSD_TEST_SERVER=<its
temporary folder>`` (SLURM jobs inherit it from the command that submits them), so the
cleanup stops exactly these processes and nothing else on the machine. Missing binaries skip
the test with the Debian packages to install; with ``CI=true`` they fail it instead.
"""

from __future__ import annotations

import os
import pwd
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import pytest

MARKER = "HERSD_TEST_SERVER"
SLURM_PACKAGES = "slurm-wlm slurmdbd munge mariadb-server"
SLURM_BINARIES = ("munged", "mariadbd", "mariadb-install-db", "slurmdbd", "slurmctld", "slurmd", "sinfo",
                  "squeue", "scancel", "sacct", "sacctmgr", "sbatch", "srun")


# --------------------------------------------------------------------------- helpers
def unavailable(message: str) -> None:
    """Skip the test, or fail it when CI=true (CI must run every test)."""
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(f"{message} (CI=true: failing instead of skipping)", pytrace=False)
    pytest.skip(message)


def require_binaries(names: tuple[str, ...], packages: str) -> None:
    """Skip (or fail under CI) unless every program in ``names`` is on PATH or in /usr/sbin."""
    missing = [name for name in names if find_binary(name) is None]
    if missing:
        unavailable(f"{', '.join(missing)} not found; install the Debian packages: apt-get install {packages}")


def find_binary(name: str) -> str | None:
    """The path of a program, also looking in the sbin folders a non-root PATH may lack."""
    return shutil.which(name) or shutil.which(name, path="/usr/sbin:/usr/local/sbin:/sbin")


def free_port() -> int:
    """A TCP port nothing listens on right now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def port_open(port: int) -> bool:
    with socket.socket() as probe:
        probe.settimeout(1)
        return probe.connect_ex(("127.0.0.1", port)) == 0


def wait_until(condition, timeout: float, what: str, logs: tuple[Path, ...] = ()) -> None:
    """Poll ``condition()`` until true; RuntimeError (with the logs' last lines) after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return
        time.sleep(0.25)
    raise RuntimeError(f"timed out after {timeout:.0f} s waiting for {what}\n" + tails(logs))


def tails(paths: tuple[Path, ...], lines: int = 15) -> str:
    """The last lines of each existing file, for error messages."""
    parts = []
    for path in paths:
        if path.exists():
            text = path.read_text(errors="replace").splitlines()[-lines:]
            parts.append(f"--- {path}\n" + "\n".join(text))
    return "\n".join(parts)


def marked_processes(marker_value: str) -> list[int]:
    """Pids of the processes whose environment holds ``HERSD_TEST_SERVER=<marker_value>``."""
    wanted = f"{MARKER}={marker_value}".encode()
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            if wanted in (entry / "environ").read_bytes().split(b"\0"):
                pids.append(int(entry.name))
        except OSError:  # gone, or not ours to read
            continue
    return pids


def kill_marked(marker_value: str, timeout: float = 10.0) -> None:
    """SIGTERM every process carrying the marker, then SIGKILL what is left after ``timeout`` s."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pid in marked_processes(marker_value):
            try:
                os.kill(pid, sig)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + timeout
        while marked_processes(marker_value) and time.monotonic() < deadline:
            time.sleep(0.2)
        if not marked_processes(marker_value):
            return


def stop(process: subprocess.Popen, timeout: float = 15.0) -> None:
    """SIGTERM a daemon we started in the foreground; SIGKILL it if it does not exit in time."""
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout)


# --------------------------------------------------------------------------- SLURM
@dataclass
class SlurmCluster:
    """A running one-node cluster: pass ``env`` to every SLURM client and ``hersd-sweep``."""

    folder: Path
    conf: Path
    partition: str
    env: dict[str, str]

    def run(self, *command: str, check: bool = True, timeout: float = 60) -> subprocess.CompletedProcess:
        """Run a SLURM client command (sinfo, squeue, sacct, ...) against this cluster."""
        return subprocess.run(list(command), env=self.env, capture_output=True, text=True, check=check,
                              timeout=timeout)

    def job_ids(self) -> list[str]:
        """Ids of the jobs still pending or running."""
        return self.run("squeue", "-h", "-o", "%i").stdout.split()

    def cancel_all(self, timeout: float = 60) -> None:
        """scancel every job and wait until the queue is empty."""
        if self.job_ids():
            self.run("scancel", "--user", _user_name(), check=False)
        wait_until(lambda: not self.job_ids(), timeout, "the cancelled jobs to leave the queue")


def _user_name() -> str:
    return pwd.getpwuid(os.getuid()).pw_name


def _memory_mb() -> int:
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemTotal:"):
            return int(line.split()[1]) // 1024
    raise RuntimeError("no MemTotal in /proc/meminfo")


def slurm_conf(folder: Path, host: str, ports: dict[str, int], partition: str) -> str:
    """slurm.conf for one node (this host, every core, 90 % of the memory) with accounting in slurmdbd."""
    cpus = os.cpu_count() or 1
    return f"""\
ClusterName=hersdtest
SlurmctldHost={host}(127.0.0.1)
SlurmctldPort={ports['slurmctld']}
SlurmdPort={ports['slurmd']}
SlurmUser={_user_name()}
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket={folder}/munge/munge.sock
StateSaveLocation={folder}/state
SlurmdSpoolDir={folder}/spool
SlurmctldPidFile={folder}/run/slurmctld.pid
SlurmdPidFile={folder}/run/slurmd.pid
SlurmctldLogFile={folder}/log/slurmctld.log
SlurmdLogFile={folder}/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU_Memory
ReturnToService=2
KillWait=2
JobAcctGatherType=jobacct_gather/linux
AccountingStorageType=accounting_storage/slurmdbd
AccountingStorageHost=127.0.0.1
AccountingStoragePort={ports['slurmdbd']}
AccountingStoragePass={folder}/munge/munge.sock
NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} RealMemory={int(_memory_mb() * 0.9)} State=UNKNOWN
PartitionName={partition} Nodes={host} Default=YES MaxTime=INFINITE State=UP
"""


def slurmdbd_conf(folder: Path, ports: dict[str, int]) -> str:
    """slurmdbd.conf: the accounting daemon, storing into the MariaDB server started next to it."""
    return f"""\
AuthType=auth/munge
AuthInfo=socket={folder}/munge/munge.sock
DbdHost=localhost
DbdAddr=127.0.0.1
DbdPort={ports['slurmdbd']}
SlurmUser={_user_name()}
PidFile={folder}/run/slurmdbd.pid
LogFile={folder}/log/slurmdbd.log
StorageType=accounting_storage/mysql
StorageHost=127.0.0.1
StoragePort={ports['mariadb']}
StorageUser=slurm
StoragePass=slurm
StorageLoc=slurm_acct_db
"""


@contextmanager
def slurm_cluster(partition: str = "hersdtest") -> Iterator[SlurmCluster]:
    """Start a one-node SLURM cluster with job accounting in a temporary folder; stop it afterwards.

    Order: munged (own key and socket), MariaDB (accounting database, TCP on 127.0.0.1),
    slurmdbd, the cluster's registration (sacctmgr), slurmctld, slurmd; ready once ``sinfo``
    shows the node idle (about 10 s). On exit: every job cancelled, the daemons stopped in
    reverse order, and any process left with the folder's marker killed.
    """
    require_binaries(SLURM_BINARIES, SLURM_PACKAGES)
    if os.geteuid() != 0:
        unavailable("the SLURM cluster test needs root (slurmd starts jobs as their user)")
    folder = Path(tempfile.mkdtemp(prefix="hersd-slurm-"))
    folder.chmod(0o755)  # munged wants every folder above its socket searchable by all
    for name in ("munge", "state", "spool", "log", "run", "mysql"):
        (folder / name).mkdir(mode=0o755)
    host = socket.gethostname().split(".")[0]
    ports = {name: free_port() for name in ("slurmctld", "slurmd", "slurmdbd", "mariadb")}
    conf = folder / "slurm.conf"
    conf.write_text(slurm_conf(folder, host, ports, partition))
    (folder / "slurmdbd.conf").write_text(slurmdbd_conf(folder, ports))  # slurmdbd reads it next to slurm.conf
    (folder / "slurmdbd.conf").chmod(0o600)
    key = folder / "munge" / "munge.key"
    key.write_bytes(os.urandom(128))
    key.chmod(0o600)
    env = {**os.environ, "SLURM_CONF": str(conf), MARKER: str(folder)}
    cluster = SlurmCluster(folder=folder, conf=conf, partition=partition, env=env)
    log = folder / "log"
    daemons: list[subprocess.Popen] = []
    ready = False

    def start(*command: str, log_name: str) -> subprocess.Popen:
        with open(log / log_name, "ab") as output:
            process = subprocess.Popen(list(command), env=env, stdout=output, stderr=subprocess.STDOUT,
                                       stdin=subprocess.DEVNULL, start_new_session=True, cwd=folder)
        daemons.append(process)
        return process

    def running(process: subprocess.Popen, what: str) -> None:
        if process.poll() is not None:
            raise RuntimeError(f"{what} exited with code {process.returncode}\n" + tails(tuple(log.iterdir())))

    try:
        munge_socket = folder / "munge" / "munge.sock"
        munged = start(find_binary("munged"), "--foreground", f"--key-file={key}", f"--socket={munge_socket}",
                       f"--pid-file={folder}/run/munged.pid", f"--log-file={log}/munged.log",
                       f"--seed-file={folder}/munge/munged.seed", log_name="munged.out")
        wait_until(lambda: running(munged, "munged") or munge_socket.exists(), 30, "munged's socket",
                   (log / "munged.log",))

        datadir = folder / "mysql" / "data"
        subprocess.run([find_binary("mariadb-install-db"), "--no-defaults", f"--datadir={datadir}",
                        f"--user={_user_name()}", "--auth-root-authentication-method=normal", "--skip-test-db"],
                       env=env, capture_output=True, check=True, timeout=120)
        init_sql = folder / "mysql" / "init.sql"
        init_sql.write_text("CREATE USER IF NOT EXISTS 'slurm'@'127.0.0.1' IDENTIFIED BY 'slurm';\n"
                            "GRANT ALL ON slurm_acct_db.* TO 'slurm'@'127.0.0.1';\n")
        mariadb = start(find_binary("mariadbd"), "--no-defaults", f"--datadir={datadir}", f"--user={_user_name()}",
                        f"--port={ports['mariadb']}", "--bind-address=127.0.0.1",
                        f"--socket={folder}/mysql/mysqld.sock", f"--pid-file={folder}/run/mariadbd.pid",
                        f"--log-error={log}/mariadb.log", f"--init-file={init_sql}", "--skip-log-bin",
                        "--innodb-buffer-pool-size=64M", log_name="mariadb.out")
        wait_until(lambda: running(mariadb, "mariadbd") or port_open(ports["mariadb"]), 60, "MariaDB",
                   (log / "mariadb.log",))

        slurmdbd = start(find_binary("slurmdbd"), "-D", log_name="slurmdbd.out")
        wait_until(lambda: running(slurmdbd, "slurmdbd") or port_open(ports["slurmdbd"]), 60, "slurmdbd",
                   (log / "slurmdbd.log",))
        wait_until(lambda: cluster.run("sacctmgr", "-i", "add", "cluster", "hersdtest", check=False).returncode == 0,
                   60, "the cluster's registration in slurmdbd", (log / "slurmdbd.log",))

        slurmctld = start(find_binary("slurmctld"), "-D", log_name="slurmctld.out")
        slurmd = start(find_binary("slurmd"), "-D", log_name="slurmd.out")

        def node_idle() -> bool:
            running(slurmctld, "slurmctld")
            running(slurmd, "slurmd")
            states = cluster.run("sinfo", "-h", "-N", "-o", "%T", check=False).stdout.split()
            return states == ["idle"]

        wait_until(node_idle, 60, "the node to be idle in sinfo", (log / "slurmctld.log", log / "slurmd.log"))
        ready = True
        yield cluster
    finally:
        try:
            if ready:
                cluster.cancel_all(timeout=30)
        except (RuntimeError, OSError, subprocess.SubprocessError):
            pass  # the marker sweep below still ends every job process
        for process in reversed(daemons):
            stop(process)
        kill_marked(str(folder))
        shutil.rmtree(folder, ignore_errors=True)


# --------------------------------------------------------------------------- PostgreSQL
def postgres_bindir() -> Path | None:
    """Debian's newest /usr/lib/postgresql/<version>/bin, else the folder of ``initdb`` on PATH."""
    versions = [p.parent for p in Path("/usr/lib/postgresql").glob("*/bin/initdb") if p.parts[-3].isdigit()]
    if versions:
        return max(versions, key=lambda bindir: int(bindir.parent.name))
    initdb = shutil.which("initdb")
    return Path(initdb).resolve().parent if initdb else None


@contextmanager
def postgres_database(name: str = "hersd", user: str = "hersd", password: str = "hersd-test") -> Iterator[str]:
    """Start a throwaway PostgreSQL server (password login over TCP on 127.0.0.1) with one
    database; yield its SQLAlchemy URL; stop the server and delete its files afterwards.

    PostgreSQL refuses to run as root, so as root the server runs as the ``postgres`` user.
    """
    bindir = postgres_bindir()
    if bindir is None or not all((bindir / tool).exists() for tool in ("initdb", "pg_ctl", "createdb")):
        unavailable("PostgreSQL's initdb/pg_ctl not found; install the Debian package: apt-get install postgresql")
    try:
        import psycopg2  # noqa: F401 - the driver hersd-search needs for postgresql:// URLs
    except ImportError:
        unavailable('psycopg2 is not installed; pip install -e ".[cluster]"')
    as_server_user: list[str] = []
    folder = Path(tempfile.mkdtemp(prefix="hersd-pg-"))
    if os.geteuid() == 0:
        try:
            owner = pwd.getpwnam("postgres")
        except KeyError:
            shutil.rmtree(folder)
            unavailable("no 'postgres' user to run PostgreSQL as; install the Debian package: "
                        "apt-get install postgresql")
        os.chown(folder, owner.pw_uid, owner.pw_gid)
        as_server_user = ["runuser", "-u", "postgres", "--"]
    port = free_port()
    data, logfile = folder / "data", folder / "server.log"
    env = {**os.environ, MARKER: str(folder), "PGPASSWORD": password}

    def run(*command: str, timeout: float = 120) -> None:
        done = subprocess.run([*as_server_user, *command], env=env, capture_output=True, text=True, timeout=timeout,
                              cwd=folder, stdin=subprocess.DEVNULL)
        if done.returncode != 0:
            raise RuntimeError(f"{' '.join(command)} failed ({done.returncode}):\n{done.stdout}{done.stderr}\n"
                               + tails((logfile,)))

    started = False
    try:
        pwfile = folder / "password"
        pwfile.write_text(password + "\n")
        if as_server_user:
            os.chown(pwfile, owner.pw_uid, owner.pw_gid)
        run(str(bindir / "initdb"), "-D", str(data), "-U", user, f"--pwfile={pwfile}", "--auth=scram-sha-256",
            "-E", "UTF8", "--no-sync")
        options = f"-p {port} -k {folder} -c listen_addresses=127.0.0.1 -c fsync=off -c synchronous_commit=off"
        run(str(bindir / "pg_ctl"), "-D", str(data), "-l", str(logfile), "-o", options, "-w", "-t", "60", "start")
        started = True
        run(str(bindir / "createdb"), "-h", "127.0.0.1", "-p", str(port), "-U", user, name)
        yield f"postgresql+psycopg2://{user}:{password}@127.0.0.1:{port}/{name}"
    finally:
        if started:
            try:
                run(str(bindir / "pg_ctl"), "-D", str(data), "-m", "fast", "-w", "-t", "30", "stop", timeout=60)
            except (RuntimeError, subprocess.SubprocessError):
                pass
        kill_marked(str(folder))
        shutil.rmtree(folder, ignore_errors=True)
