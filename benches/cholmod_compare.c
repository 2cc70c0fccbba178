/* Benchmark-only: time CHOLMOD (SuiteSparse) on the matrix `facesim bench fem --export K.mtx` wrote,
 * to compare with faer's sparse Cholesky on the same matrix. Run by benches/cholmod_compare.sh.
 * Build: gcc -O2 -I/usr/include/suitesparse cholmod_compare.c -lcholmod -o cholmod_compare */
#include <cholmod.h>
#include <stdio.h>
#include <time.h>

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

int main(int argc, char **argv) {
    if (argc != 2) { fprintf(stderr, "usage: cholmod_compare K.mtx\n"); return 2; }
    cholmod_common c;
    cholmod_start(&c);
    FILE *f = fopen(argv[1], "r");
    if (!f) { fprintf(stderr, "%s: cannot open\n", argv[1]); return 1; }
    cholmod_sparse *A = cholmod_read_sparse(f, &c);
    fclose(f);
    if (!A) { fprintf(stderr, "%s: not a Matrix Market matrix\n", argv[1]); return 1; }
    /* Three right-hand sides of ones. */
    cholmod_dense *B = cholmod_ones(A->nrow, 3, CHOLMOD_REAL, &c);
    double t0 = now();
    cholmod_factor *L = cholmod_analyze(A, &c);
    double t1 = now();
    cholmod_factorize(A, L, &c);
    double t2 = now();
    cholmod_dense *X = cholmod_solve(CHOLMOD_A, L, B, &c);
    double t3 = now();
    if (c.status != CHOLMOD_OK || !X) { fprintf(stderr, "CHOLMOD failed: status %d\n", c.status); return 1; }
    printf("{\"n\": %zu, \"nnz_l\": %.0f, \"ordering\": %d, \"seconds_analyze\": %.4f, \"seconds_factorize\": %.4f, \"seconds_three_solves\": %.4f}\n",
           A->nrow, c.lnz, L->ordering, t1 - t0, t2 - t1, t3 - t2);
    cholmod_free_dense(&X, &c);
    cholmod_free_dense(&B, &c);
    cholmod_free_factor(&L, &c);
    cholmod_free_sparse(&A, &c);
    cholmod_finish(&c);
    return 0;
}
