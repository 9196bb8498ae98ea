"""Run a command (the UML kernel) where ptrace cannot read or write the XSAVE state: `fxsave_only.py CMD ARGS`.

User-Mode Linux 6.1 (Debian bookworm's) saves a guest process's FPU state with
PTRACE_GETREGSET/SETREGSET(NT_X86_XSTATE) into an 832-byte buffer (x87, SSE,
AVX). The host kernel accepts a SETREGSET only with the host's whole XSAVE size,
so on a CPU with AVX-512 or AMX (2,696 and 10,688 bytes) every write fails with
EFAULT and the kernel dies as it starts PID 1 ("userspace - ptrace set fp regs
failed, errno = 14"). When GETREGSET(NT_X86_XSTATE) fails at start, UML uses
PTRACE_GETFPREGS/SETFPREGS (the 512-byte FXSAVE area: x87 and SSE) instead, on
any host. This launcher installs a seccomp filter that makes those two requests
fail with EIO for the command and its children, then executes the command.

Only x87/SSE state is then kept per guest context, and the host reloads the rest
as it likes on every restore (even a single-threaded guest program computed
garbage in AVX code), so the runner also keeps the guest's glibc, OpenSSL and
numpy off AVX (`_NO_AVX` in uml.py).
"""

from __future__ import annotations

import ctypes
import errno
import os
import struct
import sys

PR_SET_NO_NEW_PRIVS = 38
PR_SET_SECCOMP = 22
SECCOMP_MODE_FILTER = 2
AUDIT_ARCH_X86_64 = 0xC000003E
NR_PTRACE = 101  # x86_64
PTRACE_GETREGSET, PTRACE_SETREGSET = 0x4204, 0x4205
NT_X86_XSTATE = 0x202
SECCOMP_RET_ALLOW = 0x7FFF0000
SECCOMP_RET_ERRNO = 0x00050000
# classic BPF: load a 32-bit word of struct seccomp_data, jump if equal, return
BPF_LD_W_ABS, BPF_JEQ_K, BPF_RET_K = 0x20, 0x15, 0x06
ARCH, NR, ARG0, ARG2 = 4, 0, 16, 32  # offsets in seccomp_data (args: low 32 bits, little-endian)


def _insn(code: int, k: int, jt: int = 0, jf: int = 0) -> bytes:
    return struct.pack("HBBI", code, jt, jf, k)


def program() -> list[bytes]:
    """ptrace(GETREGSET|SETREGSET, pid, NT_X86_XSTATE, ...) fails with EIO; every other call is allowed."""
    return [
        _insn(BPF_LD_W_ABS, ARCH), _insn(BPF_JEQ_K, AUDIT_ARCH_X86_64, jf=7),
        _insn(BPF_LD_W_ABS, NR), _insn(BPF_JEQ_K, NR_PTRACE, jf=5),
        _insn(BPF_LD_W_ABS, ARG0), _insn(BPF_JEQ_K, PTRACE_GETREGSET, jt=1),
        _insn(BPF_JEQ_K, PTRACE_SETREGSET, jf=2),
        _insn(BPF_LD_W_ABS, ARG2), _insn(BPF_JEQ_K, NT_X86_XSTATE, jt=1),
        _insn(BPF_RET_K, SECCOMP_RET_ALLOW),
        _insn(BPF_RET_K, SECCOMP_RET_ERRNO | errno.EIO),
    ]


class _SockFprog(ctypes.Structure):
    _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.c_void_p)]


def install() -> None:
    """Install the filter on this process (inherited by what it executes and forks); OSError if refused."""
    insns = program()
    code = ctypes.create_string_buffer(b"".join(insns))
    fprog = _SockFprog(len(insns), ctypes.addressof(code))
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "prctl(PR_SET_NO_NEW_PRIVS)")
    if libc.prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER, ctypes.byref(fprog), 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "prctl(PR_SET_SECCOMP)")


def main(argv: list[str]) -> int:
    if not argv:
        print("usage: fxsave_only.py COMMAND [ARGS...]", file=sys.stderr)
        return 2
    try:
        install()
    except OSError as exc:  # no seccomp here: run as is (a host whose XSAVE size UML handles still boots)
        print(f"fxsave_only: cannot install the seccomp filter ({exc}); running {argv[0]} as is", file=sys.stderr)
    os.execvp(argv[0], argv)
    return 127  # not reached


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
