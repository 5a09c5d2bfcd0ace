#!/usr/bin/python3
"""A gRPC server reflection client for tests, what `grpcurl list` / `grpcurl describe` do.

Usage: reflection_client.py TARGET [--tls-ca CA_PEM] [--version v1alpha|v1] [SYMBOL...]
Prints JSON: {"services": [the names listed by the server, sorted],
              "methods": {SYMBOL: [the methods of service SYMBOL, read from the file descriptor the
                                   server returns for it]}}.
A failed call prints `CODE: details` on stderr and exits 1.

Debian 12 has neither grpcurl nor Python's grpcio-reflection, so the reflection messages
(grpc/reflection/v1alpha/reflection.proto; v1 is the same under another package) are declared
here, only the fields used, and sent with python3-grpcio's generic stream call.
"""
import argparse
import json
import sys

import grpc
from google.protobuf import descriptor_pb2, message_factory

STRING = descriptor_pb2.FieldDescriptorProto.TYPE_STRING
BYTES = descriptor_pb2.FieldDescriptorProto.TYPE_BYTES
INT32 = descriptor_pb2.FieldDescriptorProto.TYPE_INT32
MESSAGE = descriptor_pb2.FieldDescriptorProto.TYPE_MESSAGE
REPEATED = descriptor_pb2.FieldDescriptorProto.LABEL_REPEATED
OPTIONAL = descriptor_pb2.FieldDescriptorProto.LABEL_OPTIONAL

# message -> [(field, number, type, message type or "", repeated)]
MESSAGES = {
    "ServerReflectionRequest": [("host", 1, STRING, "", False),
                                ("file_containing_symbol", 4, STRING, "", False),
                                ("list_services", 7, STRING, "", False)],
    "ServerReflectionResponse": [
        ("file_descriptor_response", 4, MESSAGE, "FileDescriptorResponse", False),
        ("list_services_response", 6, MESSAGE, "ListServiceResponse", False),
        ("error_response", 7, MESSAGE, "ErrorResponse", False)],
    "FileDescriptorResponse": [("file_descriptor_proto", 1, BYTES, "", True)],
    "ListServiceResponse": [("service", 1, MESSAGE, "ServiceResponse", True)],
    "ServiceResponse": [("name", 1, STRING, "", False)],
    "ErrorResponse": [("error_code", 1, INT32, "", False), ("error_message", 2, STRING, "", False)],
}


def reflection_classes(package):
    file = descriptor_pb2.FileDescriptorProto(name="reflection_client.proto", package=package,
                                              syntax="proto3")
    for name, fields in MESSAGES.items():
        message = file.message_type.add(name=name)
        for field, number, kind, type_name, repeated in fields:
            added = message.field.add(name=field, number=number, type=kind,
                                      label=REPEATED if repeated else OPTIONAL)
            if type_name:
                added.type_name = f".{package}.{type_name}"
    classes = message_factory.GetMessages([file])
    return (classes[f"{package}.ServerReflectionRequest"],
            classes[f"{package}.ServerReflectionResponse"])


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("target")
    parser.add_argument("--tls-ca")
    parser.add_argument("--token-file", help="a file holding the bearer token (recogd with tokens "
                        "answers reflection only with one)")
    parser.add_argument("--version", default="v1alpha", choices=["v1alpha", "v1"])
    parser.add_argument("symbols", nargs="*")
    args = parser.parse_intermixed_args()
    package = f"grpc.reflection.{args.version}"
    request_class, response_class = reflection_classes(package)
    if args.tls_ca:
        with open(args.tls_ca, "rb") as f:
            channel = grpc.secure_channel(args.target, grpc.ssl_channel_credentials(f.read()))
    else:
        channel = grpc.insecure_channel(args.target)
    call = channel.stream_stream(f"/{package}.ServerReflection/ServerReflectionInfo",
                                 request_serializer=request_class.SerializeToString,
                                 response_deserializer=response_class.FromString)
    metadata = []
    if args.token_file:
        with open(args.token_file) as f:
            metadata.append(("authorization", "Bearer " + f.read().strip()))
    requests = [request_class(list_services="*")]
    requests += [request_class(file_containing_symbol=s) for s in args.symbols]
    try:
        responses = list(call(iter(requests), timeout=10, metadata=metadata))
    except grpc.RpcError as error:
        print(f"{error.code().name}: {error.details()}", file=sys.stderr)
        return 1
    result = {"services": sorted(s.name for s in responses[0].list_services_response.service),
              "methods": {}}
    for symbol, response in zip(args.symbols, responses[1:]):
        if response.HasField("error_response"):
            print(f"{symbol}: {response.error_response.error_message}", file=sys.stderr)
            return 1
        for raw in response.file_descriptor_response.file_descriptor_proto:
            file = descriptor_pb2.FileDescriptorProto.FromString(raw)
            for service in file.service:
                if f"{file.package}.{service.name}" == symbol:
                    result["methods"][symbol] = [m.name for m in service.method]
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
