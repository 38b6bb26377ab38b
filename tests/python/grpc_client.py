#!/usr/bin/python3
"""An independent gRPC client of rcand, on Python's grpcio (Debian's python3-grpcio).

usage: grpc_client.py GEN_DIR HOST:PORT TOKEN
GEN_DIR holds rcan_pb2.py and rcan_pb2_grpc.py generated from proto/rcan.proto by protoc.
Prints one JSON object with what it saw; grpc_test.cpp checks it.
"""
import json
import sys
import time
import uuid

sys.path.insert(0, sys.argv[1])
import grpc  # noqa: E402
import rcan_pb2  # noqa: E402
import rcan_pb2_grpc  # noqa: E402

M = rcan_pb2.RCANMessage


def message(mtype, payload, token=""):
    return M(version="1.0.0", message_id=str(uuid.uuid4()), type=mtype,
             payload=json.dumps(payload).encode(), timestamp_ms=int(time.time() * 1000),
             auth_token=token)


def main():
    target, token = sys.argv[2], sys.argv[3]
    out = {}
    with grpc.insecure_channel(target) as ch:
        stub = rcan_pb2_grpc.RcanStub(ch)
        auth = [("authorization", "Bearer " + token)]

        req = message(M.COMMAND, {"action": "move", "linear": 0.1, "duration_ms": 100})
        resp = stub.Send(req, metadata=auth, timeout=10)
        out["send"] = {"type": M.MessageType.Name(resp.type), "reply_matches": resp.reply_to == req.message_id,
                       "payload": json.loads(resp.payload or b"{}")}

        try:
            stub.Send(message(M.COMMAND, {"action": "status"}), timeout=10)
            out["no_token"] = {"code": "OK"}
        except grpc.RpcError as e:
            md = dict(e.trailing_metadata() or ())
            out["no_token"] = {"code": e.code().name, "rcan_error_code": md.get("rcan-error-code", "")}

        msgs = [message(M.STATUS, {}),
                message(M.COMMAND, {"action": "move", "linear": 0.1, "duration_ms": 100}),
                message(M.COMMAND, {"action": "move"})]
        msgs[2].payload = b"not json"
        want = {m.message_id for m in msgs}
        seen = {"answers": 0, "acks": 0, "errors": 0, "statuses": 0}

        def gen():
            for m in msgs:
                yield m

        call = stub.Stream(gen(), metadata=auth, timeout=20)
        for ans in call:
            if ans.reply_to in want:
                seen["answers"] += 1
                name = M.MessageType.Name(ans.type)
                if name == "ACK":
                    seen["acks"] += 1
                elif name == "ERROR":
                    seen["errors"] += 1
                elif name == "STATUS":
                    seen["statuses"] += 1
                    seen["acks"] += 1
        seen["code"] = call.code().name
        out["stream"] = seen
    print(json.dumps(out))


if __name__ == "__main__":
    main()
