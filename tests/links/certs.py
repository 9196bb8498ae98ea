"""Throwaway certificates for the locked Zenoh deployment: a lab CA and leaf certificates it signs."""

from __future__ import annotations

import datetime
import ipaddress
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID


def _name(common: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common)])


def _write(folder: Path, stem: str, key: ec.EllipticCurvePrivateKey, cert: x509.Certificate) -> tuple[Path, Path]:
    key_path, cert_path = folder / f"{stem}.key", folder / f"{stem}.pem"
    key_path.write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    return key_path, cert_path


class Authority:
    """A certificate authority in `folder`; `issue(name)` writes a key and a certificate valid for localhost."""

    def __init__(self, folder: Path, name: str) -> None:
        self.folder = folder
        self.key = ec.generate_private_key(ec.SECP256R1())
        now = datetime.datetime.now(datetime.UTC)
        day = datetime.timedelta(days=1)
        self.cert = (x509.CertificateBuilder().subject_name(_name(name)).issuer_name(_name(name))
                     .public_key(self.key.public_key()).serial_number(x509.random_serial_number())
                     .not_valid_before(now - day).not_valid_after(now + 2 * day)
                     .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
                     .sign(self.key, hashes.SHA256()))
        self.key_path, self.cert_path = _write(folder, name, self.key, self.cert)

    def issue(self, name: str) -> tuple[Path, Path]:
        key = ec.generate_private_key(ec.SECP256R1())
        now = datetime.datetime.now(datetime.UTC)
        cert = (x509.CertificateBuilder().subject_name(_name(name)).issuer_name(self.cert.subject)
                .public_key(key.public_key()).serial_number(x509.random_serial_number())
                .not_valid_before(now - datetime.timedelta(days=1)).not_valid_after(now + datetime.timedelta(days=2))
                .add_extension(x509.SubjectAlternativeName([x509.DNSName("localhost"),
                                                            x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]),
                               critical=False)
                .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
                .sign(self.key, hashes.SHA256()))
        return _write(self.folder, name, key, cert)


def mtls_config(authority: Authority, name: str) -> str:
    """A Zenoh config (JSON5) for mutual TLS: this node's certificate, the lab CA, TLS only."""
    key, cert = authority.issue(name)
    return ("{ transport: { link: { protocols: [\"tls\"], tls: { "
            f"root_ca_certificate: \"{authority.cert_path}\", enable_mtls: true, "
            f"listen_private_key: \"{key}\", listen_certificate: \"{cert}\", "
            f"connect_private_key: \"{key}\", connect_certificate: \"{cert}\" }} }} }} }}\n")


def password_config(authority: Authority, user: str, password: str, users: Path) -> str:
    """A Zenoh config (JSON5) for TLS plus user/password: the server side's certificate, the lab CA, and
    `users` (one `user:password` per line) that a listener checks connecting peers against."""
    key, cert = authority.issue("lab-server")
    return ("{ transport: { link: { protocols: [\"tls\"], tls: { "
            f"root_ca_certificate: \"{authority.cert_path}\", "
            f"listen_private_key: \"{key}\", listen_certificate: \"{cert}\" }} }}, "
            f"auth: {{ usrpwd: {{ user: \"{user}\", password: \"{password}\", "
            f"dictionary_file: \"{users}\" }} }} }} }}\n")
