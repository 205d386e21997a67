/* pn_png.h: PNG and animated PNG (APNG) files from RGB8 pixels, with nothing beyond libc: the
   deflate stream is written here (LZ77 over hash chains with a one-byte lazy look-ahead,
   dynamic Huffman codes limited to 15 bits by package-merge, a stored or fixed-code block
   whenever that is smaller), each row filtered by the rule that minimizes the sum of absolute
   differences. pn_render.h includes it; a program that only writes pixels can include it alone:

       pn_png_write("frame.png", width, height, rgb);        // rows top to bottom, 3 bytes a pixel
       pn_apng *a = pn_apng_open("anim.png", width, height, 30);
       pn_apng_add(a, rgb); ...; pn_apng_close(a);           // 30 frames a second, looping

   Every function is static; there is no mutable global state. */
#ifndef PN_PNG_H
#define PN_PNG_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* each program uses only some of these functions */
#if defined(__GNUC__)
#define PN_PNG_UNUSED __attribute__((unused))
#else
#define PN_PNG_UNUSED
#endif

/* =========================================================================================
   PNG and APNG
   ========================================================================================= */

/* growable byte buffer; fail latches the first allocation failure */
typedef struct pn_png__buf {
    unsigned char *p;
    size_t n, cap;
    int fail;
} pn_png__buf;

PN_PNG_UNUSED static int pn_png__grow(pn_png__buf *b, size_t extra) {
    size_t cap;
    unsigned char *q;
    if (b->fail) return 0;
    if (extra > (size_t)-1 / 2 - b->n) {
        b->fail = 1;
        return 0;
    }
    if (b->n + extra <= b->cap) return 1;
    cap = b->cap ? b->cap : 4096;
    while (cap < b->n + extra) cap *= 2;
    q = (unsigned char *)realloc(b->p, cap);
    if (!q) {
        b->fail = 1;
        return 0;
    }
    b->p = q;
    b->cap = cap;
    return 1;
}

PN_PNG_UNUSED static void pn_png__put(pn_png__buf *b, const void *src, size_t n) {
    if (n && pn_png__grow(b, n)) {
        memcpy(b->p + b->n, src, n);
        b->n += n;
    }
}

PN_PNG_UNUSED static void pn_png__be32(unsigned char *p, unsigned long v) {
    p[0] = (unsigned char)(v >> 24 & 255);
    p[1] = (unsigned char)(v >> 16 & 255);
    p[2] = (unsigned char)(v >> 8 & 255);
    p[3] = (unsigned char)(v & 255);
}

/* CRC-32 (polynomial 0xEDB88320, reflected), the one PNG chunks use */
PN_PNG_UNUSED static void pn_png__crc_table(unsigned long t[256]) {
    unsigned long c;
    int i, k;
    for (i = 0; i < 256; ++i) {
        c = (unsigned long)i;
        for (k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320UL ^ (c >> 1) : c >> 1;
        t[i] = c;
    }
}

PN_PNG_UNUSED static unsigned long pn_png__crc(unsigned long c, const unsigned char *p, size_t n,
                                                  const unsigned long t[256]) {
    size_t i;
    for (i = 0; i < n; ++i) c = t[(c ^ p[i]) & 255] ^ (c >> 8);
    return c;
}

/* one chunk: length, type, pre + data (fdAT puts its sequence number in pre), CRC */
PN_PNG_UNUSED static void pn_png__chunk(pn_png__buf *b, const char *type, const unsigned char *pre,
                                           size_t npre, const unsigned char *data, size_t n) {
    unsigned long tab[256], c;
    unsigned char h[8];
    pn_png__crc_table(tab);
    pn_png__be32(h, (unsigned long)(npre + n));
    memcpy(h + 4, type, 4);
    pn_png__put(b, h, 8);
    pn_png__put(b, pre, npre);
    pn_png__put(b, data, n);
    c = pn_png__crc(0xFFFFFFFFUL, h + 4, 4, tab);
    c = pn_png__crc(c, pre, npre, tab);
    c = pn_png__crc(c, data, n, tab) ^ 0xFFFFFFFFUL;
    pn_png__be32(h, c);
    pn_png__put(b, h, 4);
}

/* ---- deflate (RFC 1951) in a zlib wrapper (RFC 1950) ------------------------------------ */

#define PN_PNG__WSIZE 32768   /* the deflate window                                       */
#define PN_PNG__HBITS 15      /* hash table of 3-byte prefixes                            */
#define PN_PNG__CHAIN 48      /* candidates tried per position: speed vs. ratio           */
#define PN_PNG__NICE 128      /* a match this long ends the search                        */
#define PN_PNG__LAZY 32       /* matches shorter than this get a look one byte ahead      */
#define PN_PNG__BLOCK 32768   /* tokens per block: statistics adapt per block             */

static const unsigned short pn_png__lbase[29] = {3,  4,  5,  6,  7,  8,  9,  10, 11,  13,
                                                 15, 17, 19, 23, 27, 31, 35, 43, 51,  59,
                                                 67, 83, 99, 115, 131, 163, 195, 227, 258};
static const unsigned char pn_png__lext[29] = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2,
                                               2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0};
static const unsigned short pn_png__dbase[30] = {1,    2,    3,    4,    5,    7,     9,     13,
                                                 17,   25,   33,   49,   65,   97,    129,   193,
                                                 257,  385,  513,  769,  1025, 1537,  2049,  3073,
                                                 4097, 6145, 8193, 12289, 16385, 24577};
static const unsigned char pn_png__dext[30] = {0, 0, 0, 0, 1, 1, 2, 2,  3,  3,  4,  4,  5,  5,  6,
                                               6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13};
/* the order code-length code lengths are sent in */
static const unsigned char pn_png__clorder[19] = {16, 17, 18, 0, 8, 7, 9, 6, 10, 5,
                                                  11, 4,  12, 3, 13, 2, 14, 1, 15};

PN_PNG_UNUSED static int pn_png__log2(unsigned v) {
    int e = 0;
    while (v >>= 1) ++e;
    return e;
}
/* length 3..258 -> index into lbase (symbol 257 + index) */
PN_PNG_UNUSED static int pn_png__lcode(int len) {
    int l = len - 3, e;
    if (len == 258) return 28;
    if (l < 8) return l;
    e = pn_png__log2((unsigned)l);
    return 4 * (e - 1) + ((l >> (e - 2)) & 3);
}
/* distance 1..32768 -> distance symbol */
PN_PNG_UNUSED static int pn_png__dcode(int d) {
    int v = d - 1, e;
    if (v < 4) return v;
    e = pn_png__log2((unsigned)v);
    return 2 * e + ((v >> (e - 1)) & 1);
}

/* Code lengths of a length-limited Huffman code (package-merge): len[i] <= maxbits, 0 for
   unused symbols. One used symbol (or none) still gets a complete two-code tree, because
   zlib rejects incomplete code-length codes. n <= 288, 2^maxbits >= n. */
PN_PNG_UNUSED static void pn_png__huff_lengths(const unsigned long *freq, int n, int maxbits,
                                                  unsigned char *len) {
    int sym[288], cnt[15], m = 0, i, j, lev, k;
    unsigned long w[2][576];
    unsigned char leaf[15][576];
    for (i = 0; i < n; ++i) {
        len[i] = 0;
        if (freq[i]) { /* insertion sort by frequency: n is small */
            for (j = m; j > 0 && freq[sym[j - 1]] > freq[i]; --j) sym[j] = sym[j - 1];
            sym[j] = i;
            ++m;
        }
    }
    if (m < 2) { /* the used symbol (if any) and another one get one bit each */
        int a = m ? sym[0] : 0;
        len[a] = 1;
        len[a == 0 ? 1 : 0] = 1;
        return;
    }
    /* lists from the deepest level (leaves only) up; each list merges the leaves with the
       pairs ("packages") of the list below, both in order of weight */
    for (i = 0; i < m; ++i) {
        w[0][i] = freq[sym[i]];
        leaf[0][i] = 1;
    }
    cnt[0] = m;
    for (lev = 1; lev < maxbits; ++lev) {
        const unsigned long *pw = w[(lev - 1) & 1];
        unsigned long *cw = w[lev & 1];
        int np = cnt[lev - 1] / 2, a = 0, p = 0, c = 0;
        while (a < m || p < np) {
            unsigned long pk = p < np ? pw[2 * p] + pw[2 * p + 1] : 0;
            if (a < m && (p >= np || freq[sym[a]] <= pk)) {
                cw[c] = freq[sym[a++]];
                leaf[lev][c++] = 1;
            } else {
                cw[c] = pk;
                leaf[lev][c++] = 0;
                ++p;
            }
        }
        cnt[lev] = c;
    }
    /* the 2m - 2 lightest items of the top list; a leaf gains a bit at every level where it
       is selected, a selected package selects its two items one level down */
    k = 2 * m - 2;
    for (lev = maxbits - 1; lev >= 0; --lev) {
        int nl = 0;
        for (i = 0; i < k; ++i) nl += leaf[lev][i];
        for (i = 0; i < nl; ++i) len[sym[i]]++;
        k = 2 * (k - nl);
    }
}

/* canonical codes (RFC 1951 3.2.2), bit-reversed because deflate sends them MSB first */
PN_PNG_UNUSED static void pn_png__huff_codes(const unsigned char *len, int n, unsigned short *code) {
    int bl[16], next[16], i, b, c = 0;
    for (b = 0; b < 16; ++b) bl[b] = 0;
    for (i = 0; i < n; ++i) bl[len[i]]++;
    bl[0] = 0;
    for (b = 1; b < 16; ++b) {
        c = (c + bl[b - 1]) << 1;
        next[b] = c;
    }
    for (i = 0; i < n; ++i) {
        int v, r = 0;
        code[i] = 0;
        if (!len[i]) continue;
        v = next[len[i]]++;
        for (b = 0; b < len[i]; ++b) r |= ((v >> b) & 1) << (len[i] - 1 - b);
        code[i] = (unsigned short)r;
    }
}

/* LSB-first bit writer */
typedef struct pn_png__bw {
    pn_png__buf *b;
    unsigned long long acc;
    int nb;
} pn_png__bw;

PN_PNG_UNUSED static void pn_png__bits(pn_png__bw *w, unsigned v, int n) {
    w->acc |= (unsigned long long)v << w->nb;
    w->nb += n;
    if (w->nb >= 32) {
        if (pn_png__grow(w->b, 4)) {
            unsigned char *p = w->b->p + w->b->n;
            p[0] = (unsigned char)(w->acc & 255);
            p[1] = (unsigned char)(w->acc >> 8 & 255);
            p[2] = (unsigned char)(w->acc >> 16 & 255);
            p[3] = (unsigned char)(w->acc >> 24 & 255);
            w->b->n += 4;
        }
        w->acc >>= 32;
        w->nb -= 32;
    }
}

/* pad to a byte boundary and empty the accumulator */
PN_PNG_UNUSED static void pn_png__align(pn_png__bw *w) {
    while (w->nb > 0) {
        unsigned char c = (unsigned char)(w->acc & 255);
        pn_png__put(w->b, &c, 1);
        w->acc >>= 8;
        w->nb -= 8;
    }
    w->acc = 0;
    w->nb = 0;
}

/* tokens: a literal byte, or 0x80000000 | (length - 3) << 15 | (distance - 1) */
#define PN_PNG__MATCH 0x80000000u

/* One block of tokens covering src[s0, s1): dynamic, fixed or stored, whichever is smallest. */
PN_PNG_UNUSED static void pn_png__block(pn_png__bw *w, const unsigned *tok, size_t ntok,
                                           const unsigned char *src, size_t s0, size_t s1, int final) {
    unsigned long fl[288], fd[30], fc[19], dyn, fix, sto, ext = 0;
    unsigned char ll[288], ld[30], lc[19], fll[288], fld[30], rs[320], rx[320];
    unsigned short cl[288], cd[30], cc[19];
    const unsigned char *ul, *ud;
    const unsigned short *ucl, *ucd;
    unsigned short fcl[288], fcd[30];
    int hlit, hdist, hclen, nr = 0, i, total;
    unsigned char seq[316];
    size_t t, nsub;
    memset(fl, 0, sizeof fl);
    memset(fd, 0, sizeof fd);
    memset(fc, 0, sizeof fc);
    for (t = 0; t < ntok; ++t) {
        unsigned k = tok[t];
        if (k & PN_PNG__MATCH) {
            int lc_ = pn_png__lcode((int)((k >> 15) & 255) + 3), dc = pn_png__dcode((int)(k & 32767) + 1);
            fl[257 + lc_]++;
            fd[dc]++;
            ext += (unsigned long)pn_png__lext[lc_] + pn_png__dext[dc];
        } else {
            fl[k]++;
        }
    }
    fl[256] = 1;
    pn_png__huff_lengths(fl, 286, 15, ll);
    pn_png__huff_lengths(fd, 30, 15, ld);
    ll[286] = ll[287] = 0;
    for (hlit = 286; hlit > 257 && !ll[hlit - 1]; --hlit) {}
    for (hdist = 30; hdist > 1 && !ld[hdist - 1]; --hdist) {}
    /* run-length code the code lengths: 16 = repeat previous 3-6, 17 = 3-10 zeros, 18 = 11-138 */
    total = hlit + hdist;
    memcpy(seq, ll, (size_t)hlit);
    memcpy(seq + hlit, ld, (size_t)hdist);
    for (i = 0; i < total;) {
        int v = seq[i], run = 1;
        while (i + run < total && seq[i + run] == v) ++run;
        if (v == 0 && run >= 3) {
            while (run >= 11) {
                int r = run > 138 ? 138 : run;
                rs[nr] = 18;
                rx[nr++] = (unsigned char)(r - 11);
                run -= r;
                i += r;
            }
            if (run >= 3) {
                rs[nr] = 17;
                rx[nr++] = (unsigned char)(run - 3);
                i += run;
                run = 0;
            }
        } else if (v != 0 && run >= 4) {
            rs[nr] = (unsigned char)v;
            rx[nr++] = 0;
            ++i;
            --run;
            while (run >= 3) {
                int r = run > 6 ? 6 : run;
                rs[nr] = 16;
                rx[nr++] = (unsigned char)(r - 3);
                run -= r;
                i += r;
            }
        }
        for (; run > 0; --run, ++i) {
            rs[nr] = (unsigned char)v;
            rx[nr++] = 0;
        }
    }
    for (i = 0; i < nr; ++i) fc[rs[i]]++;
    pn_png__huff_lengths(fc, 19, 7, lc);
    for (hclen = 19; hclen > 4 && !lc[pn_png__clorder[hclen - 1]]; --hclen) {}
    /* sizes in bits */
    dyn = 3 + 14 + 3 * (unsigned long)hclen + ext;
    for (i = 0; i < nr; ++i) dyn += lc[rs[i]] + (rs[i] == 16 ? 2u : rs[i] == 17 ? 3u : rs[i] == 18 ? 7u : 0u);
    fix = 3 + ext;
    for (i = 0; i < 288; ++i) {
        fll[i] = (unsigned char)(i < 144 ? 8 : i < 256 ? 9 : i < 280 ? 7 : 8);
        dyn += fl[i] * ll[i];
        fix += fl[i] * fll[i];
    }
    for (i = 0; i < 30; ++i) {
        fld[i] = 5;
        dyn += fd[i] * ld[i];
        fix += fd[i] * 5;
    }
    nsub = (s1 - s0 + 65534) / 65535;
    if (!nsub) nsub = 1;
    sto = (unsigned long)((s1 - s0 + 4 * nsub) * 8 + nsub * 10);
    if (sto < dyn && sto < fix) {
        size_t pos = s0;
        do {
            size_t nn = s1 - pos > 65535 ? 65535 : s1 - pos;
            unsigned char h[4];
            pn_png__bits(w, final && pos + nn == s1 ? 1u : 0u, 3);
            pn_png__align(w);
            h[0] = (unsigned char)(nn & 255);
            h[1] = (unsigned char)(nn >> 8);
            h[2] = (unsigned char)(~nn & 255);
            h[3] = (unsigned char)((~nn >> 8) & 255);
            pn_png__put(w->b, h, 4);
            pn_png__put(w->b, src + pos, nn);
            pos += nn;
        } while (pos < s1);
        return;
    }
    if (fix <= dyn) {
        pn_png__huff_codes(fll, 288, fcl);
        pn_png__huff_codes(fld, 30, fcd);
        pn_png__bits(w, (final ? 1u : 0u) | 2u, 3);
        ul = fll, ud = fld, ucl = fcl, ucd = fcd;
    } else {
        pn_png__huff_codes(ll, 286, cl);
        pn_png__huff_codes(ld, 30, cd);
        pn_png__huff_codes(lc, 19, cc);
        pn_png__bits(w, (final ? 1u : 0u) | 4u, 3);
        pn_png__bits(w, (unsigned)(hlit - 257), 5);
        pn_png__bits(w, (unsigned)(hdist - 1), 5);
        pn_png__bits(w, (unsigned)(hclen - 4), 4);
        for (i = 0; i < hclen; ++i) pn_png__bits(w, lc[pn_png__clorder[i]], 3);
        for (i = 0; i < nr; ++i) {
            pn_png__bits(w, cc[rs[i]], lc[rs[i]]);
            if (rs[i] >= 16) pn_png__bits(w, rx[i], rs[i] == 16 ? 2 : rs[i] == 17 ? 3 : 7);
        }
        ul = ll, ud = ld, ucl = cl, ucd = cd;
    }
    for (t = 0; t < ntok; ++t) {
        unsigned k = tok[t];
        if (k & PN_PNG__MATCH) {
            int len = (int)((k >> 15) & 255) + 3, dist = (int)(k & 32767) + 1;
            int a = pn_png__lcode(len), dc = pn_png__dcode(dist);
            pn_png__bits(w, ucl[257 + a], ul[257 + a]);
            if (pn_png__lext[a]) pn_png__bits(w, (unsigned)(len - pn_png__lbase[a]), pn_png__lext[a]);
            pn_png__bits(w, ucd[dc], ud[dc]);
            if (pn_png__dext[dc]) pn_png__bits(w, (unsigned)(dist - pn_png__dbase[dc]), pn_png__dext[dc]);
        } else {
            pn_png__bits(w, ucl[k], ul[k]);
        }
    }
    pn_png__bits(w, ucl[256], ul[256]);
}

PN_PNG_UNUSED static unsigned pn_png__hash(const unsigned char *p) {
    unsigned long v = (unsigned long)p[0] | (unsigned long)p[1] << 8 | (unsigned long)p[2] << 16;
    return (unsigned)(((v * 2654435761UL) & 0xFFFFFFFFUL) >> (32 - PN_PNG__HBITS));
}

/* Longest match for src + pos among earlier positions with the same hash, longer than
   `better`; 0 if none. Positions >= pos are not in the chains yet. */
PN_PNG_UNUSED static int pn_png__match(const int *head, const int *prev, const unsigned char *src,
                                          size_t n, size_t pos, int better, int *dist) {
    int chain = PN_PNG__CHAIN, best = better < 2 ? 2 : better, found = 0;
    size_t maxlen = n - pos > 258 ? 258 : n - pos;
    long cand;
    const unsigned char *a = src + pos;
    if (maxlen < 3 || (size_t)best >= maxlen) return 0;
    cand = head[pn_png__hash(a)];
    while (cand >= 0 && chain-- > 0) {
        size_t d = pos - (size_t)cand;
        const unsigned char *b = src + cand;
        if (d > PN_PNG__WSIZE) break;
        if (b[best] == a[best] && b[0] == a[0] && b[1] == a[1]) {
            size_t len = 2;
            while (len < maxlen && a[len] == b[len]) ++len;
            if ((int)len > best) {
                best = (int)len;
                found = 1;
                *dist = (int)d;
                if (len >= PN_PNG__NICE || len == maxlen) break;
            }
        }
        cand = prev[cand & (PN_PNG__WSIZE - 1)];
    }
    return found ? best : 0;
}

/* src[0, n) as a zlib stream appended to out; 1 on success */
PN_PNG_UNUSED static int pn_png__zlib(const unsigned char *src, size_t n, pn_png__buf *out) {
    int *head, *prev;
    unsigned *tok;
    size_t ntok = 0, pos = 0, ins = 0, bstart = 0, i;
    unsigned long a = 1, b = 0;
    unsigned char h[4];
    pn_png__bw w;
    if (n > 0x7FFF0000UL) return 0; /* positions are ints */
    head = (int *)malloc(sizeof(int) << PN_PNG__HBITS);
    prev = (int *)malloc(sizeof(int) * PN_PNG__WSIZE);
    tok = (unsigned *)calloc(PN_PNG__BLOCK + 2, sizeof(unsigned)); /* calloc: gcc cannot see it is written first */
    if (!head || !prev || !tok) {
        free(head);
        free(prev);
        free(tok);
        return 0;
    }
    for (i = 0; i < ((size_t)1 << PN_PNG__HBITS); ++i) head[i] = -1;
    h[0] = 0x78; /* deflate, 32 KB window */
    h[1] = 0x9C; /* default level; (0x78 << 8 | 0x9C) % 31 == 0 */
    pn_png__put(out, h, 2);
    w.b = out;
    w.acc = 0;
    w.nb = 0;
    while (pos < n) {
        int len, dist = 0, len2, dist2 = 0;
        for (; ins < pos; ++ins) { /* every position goes into the chains */
            if (ins + 2 < n) {
                unsigned hh = pn_png__hash(src + ins);
                prev[ins & (PN_PNG__WSIZE - 1)] = head[hh];
                head[hh] = (int)ins;
            }
        }
        len = pn_png__match(head, prev, src, n, pos, 2, &dist);
        if (len && len < PN_PNG__LAZY && pos + 1 < n) {
            /* lazy matching: a longer match one byte on wins over this one */
            if (pos + 2 < n) {
                unsigned hh = pn_png__hash(src + pos);
                prev[pos & (PN_PNG__WSIZE - 1)] = head[hh];
                head[hh] = (int)pos;
            }
            ins = pos + 1;
            len2 = pn_png__match(head, prev, src, n, pos + 1, len, &dist2);
            if (len2) {
                tok[ntok++] = src[pos++];
                len = len2;
                dist = dist2;
            }
        }
        if (len) {
            tok[ntok++] = PN_PNG__MATCH | (unsigned)(len - 3) << 15 | (unsigned)(dist - 1);
            pos += (size_t)len;
        } else {
            tok[ntok++] = src[pos++];
        }
        if (ntok >= PN_PNG__BLOCK && pos < n) {
            pn_png__block(&w, tok, ntok, src, bstart, pos, 0);
            ntok = 0;
            bstart = pos;
        }
    }
    pn_png__block(&w, tok, ntok, src, bstart, n, 1);
    pn_png__align(&w);
    for (i = 0; i < n;) { /* adler32, reduced every 5552 bytes (no overflow in 32 bits) */
        size_t end = n - i > 5552 ? i + 5552 : n;
        for (; i < end; ++i) {
            a += src[i];
            b += a;
        }
        a %= 65521UL;
        b %= 65521UL;
    }
    pn_png__be32(h, (b << 16) | a);
    pn_png__put(out, h, 4);
    free(head);
    free(prev);
    free(tok);
    return !out->fail;
}

/* the Paeth predictor, with pa = |b - c|, pb = |a - c|, pc = |a + b - 2c| (ties: a, b, c) */
PN_PNG_UNUSED static inline int pn_png__paeth(int a, int b, int c) {
    int pa = abs(b - c), pb = abs(a - c), pc = abs(a + b - 2 * c);
    int ab = pb < pa ? b : a, pab = pb < pa ? pb : pa;
    return pc < pab ? c : ab;
}

/* add one byte's |output| under each filter; a: left, b: up, c: up-left; ab[v]: |v| of the
   byte v read as signed */
PN_PNG_UNUSED static inline void pn_png__acc(unsigned long *sum, const unsigned char *ab, int x, int a, int b,
                                                int c) {
    sum[0] += ab[x];
    sum[1] += ab[(x - a) & 255];
    sum[2] += ab[(x - b) & 255];
    sum[3] += ab[(x - ((a + b) >> 1)) & 255];
    sum[4] += ab[(x - pn_png__paeth(a, b, c)) & 255];
}

/* The filtered scanlines of an RGB8 image, zlib-compressed, appended to z. Each row takes the
   filter (None, Sub, Up, Average, Paeth) whose output has the least sum of |signed bytes|:
   one pass sums all five, a second writes the chosen one. */
PN_PNG_UNUSED static int pn_png__zimage(int w, int h, const unsigned char *rgb, pn_png__buf *z) {
    size_t stride = (size_t)w * 3, row = stride + 1, raw_n = row * (size_t)h, i;
    unsigned char *raw, *zero, ab[256];
    int y, f, ok;
    raw = (unsigned char *)malloc(raw_n);
    zero = (unsigned char *)calloc(stride, 1); /* the row above the first */
    if (!raw || !zero) {
        free(raw);
        free(zero);
        return 0;
    }
    for (i = 0; i < 256; ++i) ab[i] = (unsigned char)(i < 128 ? i : 256 - i);
    for (y = 0; y < h; ++y) {
        const unsigned char *cur = rgb + (size_t)y * stride, *up = y ? cur - stride : zero;
        unsigned char *o = raw + (size_t)y * row + 1;
        unsigned long sum[5] = {0, 0, 0, 0, 0}, best;
        int bf = 0;
        for (i = 0; i < 3; ++i) pn_png__acc(sum, ab, cur[i], 0, up[i], 0); /* nothing on the left */
        for (i = 3; i < stride; ++i) pn_png__acc(sum, ab, cur[i], cur[i - 3], up[i], up[i - 3]);
        best = sum[0];
        for (f = 1; f < 5; ++f)
            if (sum[f] < best) best = sum[f], bf = f;
        o[-1] = (unsigned char)bf;
        for (i = 0; i < stride; ++i) {
            int x = cur[i], a = i >= 3 ? cur[i - 3] : 0, b = up[i], c = i >= 3 ? up[i - 3] : 0, pr;
            switch (bf) {
            case 0: pr = 0; break;
            case 1: pr = a; break;
            case 2: pr = b; break;
            case 3: pr = (a + b) >> 1; break;
            default: pr = pn_png__paeth(a, b, c); break;
            }
            o[i] = (unsigned char)((x - pr) & 255);
        }
    }
    ok = pn_png__zlib(raw, raw_n, z);
    free(raw);
    free(zero);
    return ok;
}

/* 1 when a w x h picture is one these writers take (each side 1 .. 2^24, under 2 GB of rows) */
PN_PNG_UNUSED static int pn_png_size_ok(int w, int h) {
    return w > 0 && h > 0 && w <= (1 << 24) && h <= (1 << 24) &&
           ((double)w * 3 + 1) * (double)h < 2e9;
}

PN_PNG_UNUSED static void pn_png__ihdr(pn_png__buf *b, int w, int h) {
    unsigned char d[13];
    pn_png__put(b, "\x89PNG\r\n\x1a\n", 8);
    pn_png__be32(d, (unsigned long)w);
    pn_png__be32(d + 4, (unsigned long)h);
    d[8] = 8;                  /* bit depth */
    d[9] = 2;                  /* truecolour RGB */
    d[10] = d[11] = d[12] = 0; /* deflate, adaptive filters, no interlace */
    pn_png__chunk(b, "IHDR", NULL, 0, d, 13);
}

/* image data chunks (IDAT, or fdAT with sequence numbers from *seq), at most 1 GB each */
PN_PNG_UNUSED static void pn_png__data_chunks(pn_png__buf *b, const char *type, const pn_png__buf *z,
                                                 unsigned long *seq) {
    size_t off = 0;
    do {
        size_t nn = z->n - off > ((size_t)1 << 30) ? ((size_t)1 << 30) : z->n - off;
        unsigned char s[4];
        if (seq) pn_png__be32(s, (*seq)++);
        pn_png__chunk(b, type, s, seq ? 4 : 0, z->p + off, nn);
        off += nn;
    } while (off < z->n);
}

/* Encode a w x h RGB8 image (rows top to bottom) as PNG. *out is malloc'd (the caller frees
   it); 1 on success, 0 on bad size or out of memory (then *out is NULL). */
PN_PNG_UNUSED static int pn_png_encode(int w, int h, const unsigned char *rgb, unsigned char **out,
                                          size_t *out_n) {
    pn_png__buf z, b;
    memset(&z, 0, sizeof z);
    memset(&b, 0, sizeof b);
    *out = NULL;
    *out_n = 0;
    if (!rgb || !pn_png_size_ok(w, h) || !pn_png__zimage(w, h, rgb, &z)) {
        free(z.p);
        return 0;
    }
    pn_png__ihdr(&b, w, h);
    pn_png__data_chunks(&b, "IDAT", &z, NULL);
    pn_png__chunk(&b, "IEND", NULL, 0, NULL, 0);
    free(z.p);
    if (b.fail) {
        free(b.p);
        return 0;
    }
    *out = b.p;
    *out_n = b.n;
    return 1;
}

/* Write a w x h RGB8 image (rows top to bottom) to a PNG file; 1 on success. */
PN_PNG_UNUSED static int pn_png_write(const char *path, int w, int h, const unsigned char *rgb) {
    unsigned char *p;
    size_t n;
    FILE *f;
    int ok;
    if (!pn_png_encode(w, h, rgb, &p, &n)) return 0;
    f = fopen(path, "wb");
    if (!f) {
        free(p);
        return 0;
    }
    ok = fwrite(p, 1, n, f) == n;
    ok = (fclose(f) == 0) && ok;
    free(p);
    return ok;
}

/* Animated PNG writer: every frame full size, shown for 1/fps s, looping forever. The first
   frame is also the default image (IDAT) that viewers without APNG support show. */
typedef struct pn_apng {
    FILE *f;
    char *path;
    int w, h, fps, ok;
    unsigned long frames, seq; /* frames written; next sequence number of fcTL/fdAT */
} pn_apng;

/* Open path for a w x h animation at fps frames per second (1..65535); NULL on failure. */
PN_PNG_UNUSED static pn_apng *pn_apng_open(const char *path, int w, int h, int fps) {
    pn_apng *a;
    pn_png__buf b;
    unsigned char d[8];
    if (!path || !pn_png_size_ok(w, h) || fps < 1 || fps > 65535) return NULL;
    a = (pn_apng *)calloc(1, sizeof *a);
    if (!a) return NULL;
    a->path = (char *)malloc(strlen(path) + 1);
    if (!a->path || !(a->f = fopen(path, "wb"))) {
        free(a->path);
        free(a);
        return NULL;
    }
    strcpy(a->path, path);
    a->w = w;
    a->h = h;
    a->fps = fps;
    a->ok = 1;
    memset(&b, 0, sizeof b);
    pn_png__ihdr(&b, w, h);
    pn_png__be32(d, 0); /* num_frames: patched by pn_apng_close (acTL data sits at byte 41) */
    pn_png__be32(d + 4, 0); /* num_plays: 0 = loop forever */
    pn_png__chunk(&b, "acTL", NULL, 0, d, 8);
    a->ok = !b.fail && fwrite(b.p, 1, b.n, a->f) == b.n;
    free(b.p);
    return a;
}

/* Append one w x h RGB8 frame; 1 on success. */
PN_PNG_UNUSED static int pn_apng_add(pn_apng *a, const unsigned char *rgb) {
    pn_png__buf z, b;
    unsigned char d[26];
    if (!a || !a->ok || !rgb) return 0;
    memset(&z, 0, sizeof z);
    memset(&b, 0, sizeof b);
    if (!pn_png__zimage(a->w, a->h, rgb, &z)) {
        free(z.p);
        a->ok = 0;
        return 0;
    }
    pn_png__be32(d, a->seq++);
    pn_png__be32(d + 4, (unsigned long)a->w);
    pn_png__be32(d + 8, (unsigned long)a->h);
    pn_png__be32(d + 12, 0); /* x offset */
    pn_png__be32(d + 16, 0); /* y offset */
    d[20] = 0;
    d[21] = 1; /* delay numerator: 1 / fps s */
    d[22] = (unsigned char)(a->fps >> 8);
    d[23] = (unsigned char)(a->fps & 255);
    d[24] = 0; /* dispose: none */
    d[25] = 0; /* blend: source */
    pn_png__chunk(&b, "fcTL", NULL, 0, d, 26);
    if (a->frames == 0)
        pn_png__data_chunks(&b, "IDAT", &z, NULL);
    else
        pn_png__data_chunks(&b, "fdAT", &z, &a->seq);
    a->ok = !b.fail && fwrite(b.p, 1, b.n, a->f) == b.n;
    free(z.p);
    free(b.p);
    if (a->ok) a->frames++;
    return a->ok;
}

/* Finish the file (frame count into acTL, IEND) and free a. 1 on success; an animation
   without frames is not a valid PNG: it is removed and 0 returned. */
PN_PNG_UNUSED static int pn_apng_close(pn_apng *a) {
    pn_png__buf b;
    unsigned char d[8];
    int ok;
    if (!a) return 0;
    memset(&b, 0, sizeof b);
    pn_png__chunk(&b, "IEND", NULL, 0, NULL, 0);
    ok = a->ok && !b.fail && fwrite(b.p, 1, b.n, a->f) == b.n;
    free(b.p);
    memset(&b, 0, sizeof b);
    pn_png__be32(d, a->frames);
    pn_png__be32(d + 4, 0);
    pn_png__chunk(&b, "acTL", NULL, 0, d, 8);
    /* rewrite acTL in place: same length, so only its data and CRC change */
    ok = ok && !b.fail && fseek(a->f, 33, SEEK_SET) == 0 && fwrite(b.p, 1, b.n, a->f) == b.n;
    free(b.p);
    ok = (fclose(a->f) == 0) && ok;
    if (a->frames == 0) {
        remove(a->path);
        ok = 0;
    }
    free(a->path);
    free(a);
    return ok;
}

#endif /* PN_PNG_H */
