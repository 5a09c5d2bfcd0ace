#!/usr/bin/python3
"""A DNS server for tests, on UDP 127.0.0.1 (a free port, written to PORT_FILE once bound).

Usage: tiny_dns.py RECORDS_FILE PORT_FILE. RECORDS_FILE holds `name address` lines (IPv4; a name
on several lines has several addresses); it is read anew for every query, so a test moves a name
by rewriting the file. A query for a listed name gets its A records with a TTL of 1 s (other
types: no answer); any other name gets NXDOMAIN.
Runs until killed.
"""
import os
import socket
import struct
import sys


def read_records(path):
    records = {}
    with open(path, encoding="ascii") as f:
        for line in f:
            fields = line.split()
            if len(fields) == 2:
                records.setdefault(fields[0].lower().rstrip("."), []).append(fields[1])
    return records


def answer(query, records):
    ident, = struct.unpack("!H", query[:2])
    pos, labels = 12, []
    while query[pos]:
        labels.append(query[pos + 1:pos + 1 + query[pos]].decode("ascii"))
        pos += 1 + query[pos]
    question_end = pos + 5
    qtype, = struct.unpack("!H", query[pos + 1:pos + 3])
    addresses = records.get(".".join(labels).lower())
    rcode = 3 if addresses is None else 0
    if addresses is None or qtype != 1:
        addresses = []
    # A records: a pointer to the question's name, type A, class IN, TTL 1 s, 4 bytes.
    answers = b"".join(b"\xc0\x0c" + struct.pack("!HHIH", 1, 1, 1, 4) + socket.inet_aton(a)
                       for a in addresses)
    header = struct.pack("!HHHHHH", ident, 0x8400 | 0x0100 | rcode, 1, len(addresses), 0, 0)
    return header + query[12:question_end] + answers


def main():
    records_file, port_file = sys.argv[1:3]
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    with open(port_file + ".part", "w", encoding="ascii") as f:
        f.write(str(sock.getsockname()[1]))
    os.rename(port_file + ".part", port_file)
    while True:
        query, client = sock.recvfrom(512)
        sock.sendto(answer(query, read_records(records_file)), client)


if __name__ == "__main__":
    main()
