"""Open MPI settings for every process the project starts that runs MPI: participants under
``mpirun`` or alone (dolfinx initialises MPI in a one-rank solid too), and the OpenFOAM solvers
on N ranks. They travel as ``OMPI_MCA_*`` environment variables, which mpirun forwards to its
daemons and ranks.

One host (the default): shared memory between the ranks (``btl self,vader``: without the TCP
BTL no rank listens, where each used to listen on ``0.0.0.0`` and ``::`` from port 1024),
mpirun's wire-up over loopback (``oob_tcp_if_include lo``), and a process that initialises MPI
without mpirun does not fork the ``orted`` that would listen on all interfaces
(``ess_singleton_isolated``; it cannot ``MPI_Comm_spawn``, which nothing here does).
Several hosts: name the interfaces (``VARCOUPLE_MPI_INTERFACES=eth0`` or the ``interfaces``
argument; names or CIDR networks, as Open MPI's ``*_if_include``): the TCP BTL comes back, on
those only, and the wire-up uses them. Both: messaging layer ob1 (the BTLs above; also the
quicker start-up, see :meth:`fluid_openfoam.parallel.Decomposition.mpi_command`).

mpirun itself binds its out-of-band (ORTE) listener to the wildcard address, IPv4 and IPv6,
whatever ``oob_tcp_if_include`` says (Open MPI 4.1, ``orte/mca/oob/tcp/oob_tcp_listener.c``:
``INADDR_ANY``); on one host the settings preload a small library (``LD_PRELOAD``:
``_loopback/loopback_bind.c``, built with the kernels) that binds such sockets to loopback, in
mpirun and whatever else is started with them.
A process of ours that initialises MPI itself (``varcouple``'s own process: mpi4py, petsc4py and
dolfinx do on import) reads them from its own environment: :func:`confine` puts them there
first (without them Open MPI's singleton listened on ``0.0.0.0:1024`` and forked an ``orted``
listening on all interfaces). With ``VARCOUPLE_MPI_SESSION`` (the run's, :mod:`.mpi_session`) the
session directory and the shared-memory segments go there.
tests/coupler/test_mpi_loopback.py reads every listening socket of the processes a run starts.
"""

from __future__ import annotations

import os
from importlib import resources
from typing import Mapping, MutableMapping

from coupler.protocol.mpi_session import SESSION_VAR, shared_memory_dir

INTERFACES_VAR = "VARCOUPLE_MPI_INTERFACES"


def mpi_environment(interfaces: list[str] | None = None, env: Mapping[str, str] | None = None) -> dict[str, str]:
    """A copy of ``env`` (default ``os.environ``) with the Open MPI settings above.
    ``interfaces``: network interfaces for a run over several hosts; None reads the
    comma-separated ``VARCOUPLE_MPI_INTERFACES`` of ``env``. Named interfaces replace the
    transport settings ``env`` has; without them (this host only) every setting ``env``
    already has wins."""
    out = outside_job(os.environ if env is None else env)
    if interfaces is None:
        interfaces = out.get(INTERFACES_VAR, "").split(",")
    interfaces = [i.strip() for i in interfaces if i.strip()]
    for name in interfaces:
        if any(c.isspace() or c == "," for c in name):
            raise ValueError(f"MPI interface {name!r}: one interface name or CIDR network per entry")
    session = out.get(SESSION_VAR)
    if session:  # this run's own session directory and shared memory (coupler/protocol/mpi_session.py)
        out.update({"OMPI_MCA_orte_tmpdir_base": session,
                    "OMPI_MCA_btl_vader_backing_directory": shared_memory_dir(session)})
    defaults = {"pml": "ob1", "ess_singleton_isolated": "1"}
    if interfaces:
        names = ",".join(interfaces)
        out.update({"OMPI_MCA_btl": "self,vader,tcp", "OMPI_MCA_btl_tcp_if_include": names,
                    "OMPI_MCA_oob_tcp_if_include": names})
    else:
        defaults.update(btl="self,vader", oob_tcp_if_include="lo")
        library = loopback_library()
        preloaded = out.get("LD_PRELOAD", "").split()
        if library is not None and library not in preloaded:
            out["LD_PRELOAD"] = " ".join([library, *preloaded])
    for key, value in defaults.items():
        out.setdefault(f"OMPI_MCA_{key}", value)
    # Open MPI refuses to start as root without these (containers, CI).
    out.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
    out.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    return out


def confine(env: MutableMapping[str, str] | None = None) -> None:
    """Put the settings of :func:`mpi_environment` into ``env`` (default ``os.environ``: this
    process's own, which Open MPI reads when this process initialises MPI, so call it before
    anything imports mpi4py, petsc4py or dolfinx; the processes it starts inherit them). In a
    process mpirun started, the settings its job was given stay; the missing ones are added."""
    env = os.environ if env is None else env
    settings = mpi_environment(env=env)
    if in_job(env):
        settings = {key: value for key, value in settings.items() if key not in env}
    else:  # a parent's singleton leftovers would make this process's MPI, and its mpiruns, fail
        for key in SINGLETON_VARIABLES:
            env.pop(key, None)
    env.update(settings)


#: what mpirun tells the processes of its job (Open MPI, PMIx): a process started by one of them
#: (a participant of a coupler on several ranks) must not inherit it, or it would join that job
JOB_VARIABLES = ("OMPI_", "PMIX_", "OPAL_", "ORTE_", "HWLOC_")


#: what an isolated singleton (a process that initialised MPI without mpirun, as varcouple's own
#: and pytest's do) writes into its C environment: its children inherit them, and an mpirun that
#: sees ``OMPI_MCA_ess=singleton`` exits 1 without a word
SINGLETON_VARIABLES = ("OMPI_MCA_ess", "OMPI_MCA_pmix", "OMPI_MCA_orte_ess_num_procs", "OMPI_APP_CTX_NUM_PROCS",
                       "OMPI_MCA_orte_precondition_transports")


def outside_job(env: Mapping[str, str]) -> dict[str, str]:
    """A copy of `env` without the variables of the MPI job it runs in, if any (then every
    ``OMPI_*`` goes: mpirun sets its own ``OMPI_MCA_*`` among them), or of the singleton a parent
    process was (:data:`SINGLETON_VARIABLES`)."""
    if not in_job(env):
        return {k: v for k, v in env.items() if k not in SINGLETON_VARIABLES}
    return {k: v for k, v in env.items() if not k.startswith(JOB_VARIABLES)}


def in_job(env: Mapping[str, str]) -> bool:
    """`env` is that of a process mpirun started."""
    return "OMPI_COMM_WORLD_SIZE" in env or "PMIX_RANK" in env


def loopback_library() -> str | None:
    """The installed library that binds wildcard listeners to loopback (None if not built)."""
    path = resources.files("coupler.protocol").joinpath("libloopback_bind.so")
    return str(path) if path.is_file() else None
