"""Child process of test_store_concurrency.py and benchmarks/store_filing.py: files calibration
files into a store.

Usage: python _store_writer.py STORE FILES_DIR LIST [hang].  STORE is a folder or a database
URL, LIST a text file of calibration paths (one a line), filed in that order; prints
"filed NEW ALREADY" at the end.  With "hang", the first filing stops inside its transaction
(after its calibrations row, before its parameters), prints "in transaction" and waits to be
killed (it gives up after 120 s).
"""
import sys
import time


def main(store, files, listing, mode=None):
    from station.io import store_backend
    from station.io.history import Store

    if mode == "hang":
        def hang(self, sql, seq):
            print("in transaction", flush=True)
            time.sleep(120)
        store_backend.Tx.many = hang
    paths = [line for line in open(listing).read().splitlines() if line]
    new = already = 0
    with Store(store, files=files) as s:
        for path in paths:
            _, was_new = s.file(path)
            new += was_new
            already += not was_new
    print(f"filed {new} {already}", flush=True)


if __name__ == "__main__":
    main(*sys.argv[1:])
