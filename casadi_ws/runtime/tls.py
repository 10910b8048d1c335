"""TLS for a Dask cluster: the credentials ``casadi-ws cluster-certs`` writes, and the client's side of them.

A Dask scheduler listening on ``tcp://`` runs whatever any client that reaches its port sends it (tasks are
pickled functions). With ``--protocol tls`` and these files, scheduler, workers and client each prove that
they hold a certificate signed by the same private authority, and their traffic is encrypted: only machines
the folder was copied to take part. One certificate serves all three (Dask checks the authority, not host
names), so the folder is what a user copies to each machine; its private keys are readable by their owner
only.
"""

from __future__ import annotations

import datetime
import os
from pathlib import Path

__all__ = ["FILES", "security", "write_certificates"]

FILES = {"ca": "ca.pem", "cert": "cluster.pem", "key": "cluster-key.pem"}
"""The files of a credentials folder: the authority's certificate, the cluster's certificate and its key."""


def write_certificates(folder: str | Path, days: int = 365) -> dict:
    """A private certificate authority and one certificate signed by it, for the scheduler, the workers and the
    client, valid ``days`` days, written into ``folder`` (PEM). Returns {role: path}."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    now = datetime.datetime.now(datetime.timezone.utc)
    until = now + datetime.timedelta(days=days)
    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "casadi-ws cluster authority")])
    ca = (x509.CertificateBuilder().subject_name(ca_name).issuer_name(ca_name).public_key(ca_key.public_key())
          .serial_number(x509.random_serial_number()).not_valid_before(now).not_valid_after(until)
          .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
          .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=True, crl_sign=True,
                                       content_commitment=False, key_encipherment=False, data_encipherment=False,
                                       key_agreement=False, encipher_only=False, decipher_only=False), critical=True)
          .sign(ca_key, hashes.SHA256()))
    key = ec.generate_private_key(ec.SECP256R1())
    cert = (x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "casadi-ws cluster")]))
            .issuer_name(ca_name).public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now).not_valid_after(until)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]),
                           critical=False)
            .sign(ca_key, hashes.SHA256()))
    d = Path(folder)
    d.mkdir(parents=True, exist_ok=True)
    paths = {role: d / name for role, name in FILES.items()}
    paths["ca"].write_bytes(ca.public_bytes(serialization.Encoding.PEM))
    paths["cert"].write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    fd = os.open(paths["key"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                  serialization.NoEncryption()))
    return paths


def security(folder: str | Path):
    """The client's :class:`distributed.Security` from a credentials folder (encryption required); ValueError
    naming a missing file."""
    from distributed import Security

    d = Path(folder)
    missing = [name for name in FILES.values() if not (d / name).is_file()]
    if missing:
        raise ValueError(f"{d}: no {', '.join(missing)} (casadi-ws cluster-certs --out {d} writes them)")
    return Security(tls_ca_file=str(d / FILES["ca"]), tls_client_cert=str(d / FILES["cert"]),
                    tls_client_key=str(d / FILES["key"]), require_encryption=True)
