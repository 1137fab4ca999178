// tools/fwref_hover.cpp -- scope: runs fwref/hover.hpp over recorded flights for tests/test_hover.py.
//
//   fwref_hover --in FLIGHTS.f32 --samples T --out EST.bin
//
// FLIGHTS.f32: F flights x T samples x 9 little-endian float32 (vz, roll, pitch, thr1..thr4, I_b,
// airborne as 0/1; NaN = no sample). EST.bin: per flight cmd (float32), cur (float32), freeze
// (int32, -1 = never), the estimate's bits as computed, for a bit-for-bit comparison.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "fwref/hover.hpp"

int main(int argc, char** argv) {
    const char* in = nullptr;
    const char* out = nullptr;
    long samples = 0;
    for (int a = 1; a + 1 < argc; a += 2) {
        if (!std::strcmp(argv[a], "--in")) in = argv[a + 1];
        else if (!std::strcmp(argv[a], "--out")) out = argv[a + 1];
        else if (!std::strcmp(argv[a], "--samples")) samples = std::atol(argv[a + 1]);
    }
    if (!in || !out || samples <= 0) {
        std::fprintf(stderr, "usage: fwref_hover --in FLIGHTS.f32 --samples T --out EST.bin\n");
        return 2;
    }
    FILE* f = std::fopen(in, "rb");
    if (!f) { std::fprintf(stderr, "fwref_hover: cannot open %s\n", in); return 2; }
    std::vector<float> data;
    float buf[9];
    while (std::fread(buf, sizeof(float), 9, f) == 9) data.insert(data.end(), buf, buf + 9);
    std::fclose(f);
    const long per = samples * 9;
    if (data.empty() || data.size() % per != 0) {
        std::fprintf(stderr, "fwref_hover: %s does not hold whole flights of %ld samples\n", in, samples);
        return 2;
    }
    FILE* o = std::fopen(out, "wb");
    if (!o) { std::fprintf(stderr, "fwref_hover: cannot write %s\n", out); return 2; }
    for (size_t start = 0; start < data.size(); start += per) {
        fwref::HoverEstimator<50> h;
        for (long t = 0; t < samples; ++t) {
            const float* s = &data[start + t * 9];
            h.push(s[0], s[1], s[2], s + 3, s[7], s[8] != 0.0f);
        }
        const float cmd = h.cmd(), cur = h.cur();
        const int32_t fz = h.freeze_index();
        std::fwrite(&cmd, 4, 1, o);
        std::fwrite(&cur, 4, 1, o);
        std::fwrite(&fz, 4, 1, o);
    }
    std::fclose(o);
    return 0;
}
