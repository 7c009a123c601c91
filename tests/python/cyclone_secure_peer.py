"""Cyclone DDS 0.10 (Debian's libddsc0debian, with its DDS Security plugins) as a secured peer of
equiarm's nodes: publishes or prints EpisodeResults on /episodes in an enclave made by `equiarm
security`. Not run by the test command: the handshake with RustDDS 0.15.1 fails (docs/security.md,
"Interoperability with Cyclone DDS"); this is the reproduction.

    cyclone_secure_peer.py pub|sub DOMAIN SECONDS ENCLAVE_DIR

Needs Cyclone's Python binding built against the system library (the wheel on PyPI has no security
plugins): a CYCLONEDDS_HOME with lib/ (links to /usr/lib/x86_64-linux-gnu/libddsc* and
libcycloneddsidl*), include/ (/usr/include) and bin/idlc, then `pip install cyclonedds==0.10.2`.
CY_EXTRA adds XML inside <Domain> (say, <Tracing>).
"""
import json
import os
import sys
import time

mode, domain, seconds, enclave = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
plugins = "/usr/lib/x86_64-linux-gnu/libddsc0debian"
f = lambda n: f"file:{os.path.join(enclave, n)}"
xml = f"""<CycloneDDS><Domain id="any"><Security>
<Authentication><Library path="{plugins}/libdds_security_auth.so" initFunction="init_authentication" finalizeFunction="finalize_authentication"/>
<IdentityCertificate>{f('cert.pem')}</IdentityCertificate><IdentityCA>{f('identity_ca.cert.pem')}</IdentityCA><PrivateKey>{f('key.pem')}</PrivateKey><IncludeOptionalFields>true</IncludeOptionalFields></Authentication>
<AccessControl><Library path="{plugins}/libdds_security_ac.so" initFunction="init_access_control" finalizeFunction="finalize_access_control"/>
<PermissionsCA>{f('permissions_ca.cert.pem')}</PermissionsCA><Governance>{f('governance.p7s')}</Governance><Permissions>{f('permissions.p7s')}</Permissions></AccessControl>
<Cryptographic><Library path="{plugins}/libdds_security_crypto.so" initFunction="init_crypto" finalizeFunction="finalize_crypto"/></Cryptographic>
</Security>{os.environ.get('CY_EXTRA','')}</Domain></CycloneDDS>"""
os.environ["CYCLONEDDS_URI"] = xml
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration
# EpisodeResult and its parts as in tests/python/equiarm_idl.py, declared again: that module is written
# for the current binding (cyclonedds 11), whose IDL machinery the 0.10 binding lacks.
from dataclasses import dataclass, field
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float32, int32, uint32, uint64


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class EpisodeResult(IdlStruct, typename="equiarm_msgs::msg::dds_::EpisodeResult_"):
    header: Header = field(default_factory=Header)
    env: str = ""
    task: str = ""
    seed: uint64 = 0
    episode: uint32 = 0
    steps: uint32 = 0
    success: bool = False
    ret: float32 = 0.0
    discounted_return: float32 = 0.0
    expert: bool = False
    eval: bool = False


class idl:
    EpisodeResult = EpisodeResult
qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile, Policy.History.KeepLast(100))
dp = DomainParticipant(domain)
t = Topic(dp, "rt/episodes", idl.EpisodeResult)
end = time.monotonic() + seconds
n = 0
if mode == "pub":
    w = DataWriter(dp, t, qos=qos)
    while time.monotonic() < end:
        w.write(idl.EpisodeResult(env="cyclone", task="block_pulling", seed=7, episode=n, steps=9, success=True, ret=1.0, discounted_return=0.92))
        n += 1; time.sleep(0.1)
    print(json.dumps({"sent": n}), flush=True)
else:
    r = DataReader(dp, t, qos=qos)
    got = []
    while time.monotonic() < end:
        for s in r.take(N=100):
            if hasattr(s, "__dataclass_fields__"):
                got.append((s.env, s.episode))
        time.sleep(0.05)
    print(json.dumps({"received": len(got), "first": got[:3]}), flush=True)
