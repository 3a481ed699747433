"""A child for the zygote tests (``python -m zygote_child MODE [CODE]``): ``report CODE`` prints
its argv, test variable, session and stdin, then exits with CODE; ``wait`` prints ``ready`` and
blocks until signalled; ``raise``: an exception; ``refuse``: ``SystemExit`` with a message."""
import json
import os
import signal
import sys

if __name__ == '__main__':
    mode = sys.argv[1]
    if mode == 'report':
        print(json.dumps({'argv': sys.argv[1:], 'var': os.environ.get('ZYGOTE_TEST'),
                          'sid': os.getsid(0), 'pgid': os.getpgid(0), 'pid': os.getpid(),
                          'stdin': sys.stdin.read()}), flush=True)
        sys.exit(int(sys.argv[2]))
    if mode == 'wait':
        print('ready', flush=True)
        while True:
            signal.pause()
    if mode == 'raise':
        raise RuntimeError('boom in the child')
    raise SystemExit('refused: bad configuration')
