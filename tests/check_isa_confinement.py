#!/usr/bin/env python3
"""Fails when AVX or AVX-512 code is found outside the wide kernels in a portable build.

The wide kernels are compiled once per instruction set (src/trace/wide_traversal_*.cpp). A
function they share with the rest of the program, if not inlined, is emitted once per
translation unit and the linker keeps one copy for every caller: when that copy comes from
the AVX-512 unit, a baseline caller crashes on a CPU without AVX-512. (mt_direction_scale
was such a function.) In a build without -march flags no function outside the kernels'
namespace may therefore hold a VEX or EVEX instruction.

Usage: check_isa_confinement.py EXECUTABLE
"""
import re
import subprocess
import sys


def main() -> int:
    exe = sys.argv[1]
    listing = subprocess.run(["objdump", "-d", "--no-show-raw-insn", "-C", exe],
                             capture_output=True, text=True, check=True).stdout
    function, leaks, kernels = None, {}, 0
    start, data_end = 0, 0
    for line in listing.splitlines():
        header = re.match(r"^([0-9a-f]+) <(.*)>:$", line)
        if header:
            start, data_end = int(header.group(1), 16), 0
            function = header.group(2)
            kernels += "bvhopt::wide_kernels::" in function
            continue
        if function is None or "bvhopt::wide_kernels::" in function:
            continue
        fields = line.split("\t")
        if len(fields) < 2:
            continue
        address = int(fields[0].strip().rstrip(":"), 16)
        instruction = fields[-1].strip()
        # clang's -fsanitize=function puts 8 bytes before each function's code, jumped over:
        # a signature and the address of the function's type. objdump decodes those bytes as
        # instructions too, and an address can read as one with a v (a sanitizer build once
        # showed 'vmwrite'), so they are skipped.
        if address == start and re.match(r"jmp\s+[0-9a-f]+ <.*\+0x8>$", instruction):
            data_end = start + 8
            continue
        if address < data_end:
            continue
        # VEX and EVEX mnemonics start with v (vmovd, vxorps, ...); ymm and zmm registers
        # exist only with AVX.
        if re.match(r"v[a-z]", instruction) or "%ymm" in instruction or "%zmm" in instruction:
            leaks.setdefault(function, instruction)
    if kernels == 0:
        print(f"{exe}: no wide kernel functions found; the check would mean nothing")
        return 1
    for function, instruction in leaks.items():
        print(f"{exe}: {function} holds '{instruction}', compiled for a wider instruction set than the build's")
    print(f"{kernels} kernel functions, {len(leaks)} functions outside them with AVX code")
    return 1 if leaks else 0


if __name__ == "__main__":
    sys.exit(main())
