/* Run-time look-up of the BLAS that the dynamic loader gave this process and
 * of its thread controls, for the Fortran module blas_threads (the only
 * caller). No header and no link-time symbol of any BLAS is used: every
 * function is found with dlsym(RTLD_DEFAULT, ...) and called through the
 * prototypes below, so the program links and runs with the reference BLAS,
 * OpenBLAS (serial, pthread, openmp), BLIS or MKL alike.
 *
 * Prototypes, as the libraries document them:
 *   OpenBLAS: void openblas_set_num_threads(int); int openblas_get_num_threads(void);
 *             char *openblas_get_config(void); int openblas_get_parallel(void)
 *             (0 sequential, 1 pthreads, 2 OpenMP)
 *   BLIS:     void bli_thread_set_num_threads(dim_t); dim_t bli_thread_get_num_threads(void);
 *             char *bli_info_get_version_str(void) (dim_t is int64_t on LP64 builds)
 *   MKL:      void MKL_Set_Num_Threads(int); int MKL_Get_Max_Threads(void);
 *             void MKL_Get_Version_String(char *, int)
 *   OpenBLAS built with DYNAMIC_ARCH (Debian's) also exports
 *             char *openblas_get_corename(void), and the pair
 *             void gotoblas_dynamic_quit(void); void gotoblas_dynamic_init(void)
 *             that forgets and chooses again the table of kernels; the choice
 *             reads OPENBLAS_CORETYPE when it is set (the library's documented
 *             variable), else the CPU model.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <limits.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

/* Kinds of BLAS; the same values are parameters of the Fortran module. */
enum { FC_BLAS_UNKNOWN = 0, FC_BLAS_OPENBLAS = 1, FC_BLAS_BLIS = 2, FC_BLAS_MKL = 3 };

typedef void (*set_int_fn)(int);
typedef int (*get_int_fn)(void);
typedef char *(*get_str_fn)(void);
typedef void (*set_dim_fn)(int64_t);
typedef int64_t (*get_dim_fn)(void);
typedef void (*version_fn)(char *, int);

static void *symbol(const char *name) { return dlsym(RTLD_DEFAULT, name); }

/* Copy `src` into the buffer `dst` of `n` bytes, NUL-terminated. */
static void copy_text(char *dst, int n, const char *src) {
  if (n <= 0) return;
  snprintf(dst, (size_t)n, "%s", src ? src : "");
}

/* The kind of BLAS whose thread controls dlsym(handle, ...) sees (OpenBLAS first: it is
 * what Debian's libblas.so.3 alternatives most often are). */
static int kind_in(void *handle) {
  if (dlsym(handle, "openblas_get_config") && dlsym(handle, "openblas_set_num_threads")) return FC_BLAS_OPENBLAS;
  if (dlsym(handle, "bli_thread_set_num_threads") && dlsym(handle, "bli_thread_get_num_threads")) return FC_BLAS_BLIS;
  if (dlsym(handle, "MKL_Set_Num_Threads") && dlsym(handle, "MKL_Get_Max_Threads")) return FC_BLAS_MKL;
  return FC_BLAS_UNKNOWN;
}

/* The kind of the library that provides dgemm_, searched in that library and
 * the libraries it depends on (Debian's OpenBLAS libblas.so.3 is a thin layer
 * over libopenblas.so.0; the reference libblas.so.3 has no thread control even
 * when an OpenBLAS liblapack.so.3 is loaded too). */
int fc_blas_owner_kind(void) {
  Dl_info info;
  void *dgemm = symbol("dgemm_");
  int kind = FC_BLAS_UNKNOWN;
  if (!dgemm || !dladdr(dgemm, &info) || !info.dli_fname) return FC_BLAS_UNKNOWN;
  void *handle = dlopen(info.dli_fname, RTLD_LAZY | RTLD_NOLOAD);
  if (!handle) return kind_in(RTLD_DEFAULT);  /* e.g. dgemm_ linked into the program */
  kind = kind_in(handle);
  dlclose(handle);
  return kind;
}

/* Bit (1 << kind) set for each kind of BLAS thread control present anywhere
 * in the process (a LAPACK or another library may bring its own BLAS). */
int fc_blas_kinds(void) {
  int mask = 0;
  if (symbol("openblas_get_config") && symbol("openblas_set_num_threads")) mask |= 1 << FC_BLAS_OPENBLAS;
  if (symbol("bli_thread_set_num_threads") && symbol("bli_thread_get_num_threads")) mask |= 1 << FC_BLAS_BLIS;
  if (symbol("MKL_Set_Num_Threads") && symbol("MKL_Get_Max_Threads")) mask |= 1 << FC_BLAS_MKL;
  return mask;
}

/* Name and version of the BLAS of `kind` in `name`; `threaded` is 1 when it
 * can run more than one thread, 0 when it is a sequential build. */
void fc_blas_describe(int kind, char *name, int name_len, int *threaded) {
  char buf[512];
  *threaded = 0;
  switch (kind) {
  case FC_BLAS_OPENBLAS: {
    get_str_fn config = (get_str_fn)symbol("openblas_get_config");
    get_int_fn parallel = (get_int_fn)symbol("openblas_get_parallel");
    const char *text = config ? config() : NULL;
    char version[64] = "";
    /* the configuration string starts with "OpenBLAS <version> ..." */
    if (text && sscanf(text, "OpenBLAS %63s", version) != 1) version[0] = '\0';
    int mode = parallel ? parallel() : -1;
    const char *modes[] = {"serial", "pthread", "openmp"};
    snprintf(buf, sizeof buf, "OpenBLAS%s%s (%s)", version[0] ? " " : "", version,
             mode >= 0 && mode <= 2 ? modes[mode] : "threading unknown");
    *threaded = mode == 1 || mode == 2;
    break;
  }
  case FC_BLAS_BLIS: {
    get_str_fn version = (get_str_fn)symbol("bli_info_get_version_str");
    get_dim_fn pthreads = (get_dim_fn)symbol("bli_info_get_enable_pthreads");
    get_dim_fn openmp = (get_dim_fn)symbol("bli_info_get_enable_openmp");
    int pt = pthreads ? pthreads() != 0 : 0, om = openmp ? openmp() != 0 : 0;
    snprintf(buf, sizeof buf, "BLIS %s (%s)", version ? version() : "", pt ? "pthread" : om ? "openmp" : "serial");
    *threaded = pt || om;
    break;
  }
  case FC_BLAS_MKL: {
    version_fn version = (version_fn)symbol("MKL_Get_Version_String");
    char text[256] = "Intel MKL";
    if (version) version(text, (int)sizeof text - 1);
    text[sizeof text - 1] = '\0';
    for (int i = (int)strlen(text) - 1; i >= 0 && text[i] == ' '; --i) text[i] = '\0';
    snprintf(buf, sizeof buf, "%s", text);
    *threaded = 1;
    break;
  }
  default:
    snprintf(buf, sizeof buf, "reference or unknown BLAS");
  }
  copy_text(name, name_len, buf);
}

/* The file of the library that provides dgemm_ (symbolic links resolved), or
 * "unknown". */
void fc_blas_path(char *path, int path_len) {
  Dl_info info;
  void *dgemm = symbol("dgemm_");
  char resolved[PATH_MAX];
  if (dgemm && dladdr(dgemm, &info) && info.dli_fname && info.dli_fname[0]) {
    if (realpath(info.dli_fname, resolved))
      copy_text(path, path_len, resolved);
    else
      copy_text(path, path_len, info.dli_fname);
  } else {
    copy_text(path, path_len, "unknown");
  }
}

/* Threads the BLAS of `kind` will use; 1 when it has no thread control. */
int fc_blas_get_threads(int kind) {
  switch (kind) {
  case FC_BLAS_OPENBLAS: {
    get_int_fn get = (get_int_fn)symbol("openblas_get_num_threads");
    return get ? get() : 1;
  }
  case FC_BLAS_BLIS: {
    get_dim_fn get = (get_dim_fn)symbol("bli_thread_get_num_threads");
    int64_t n = get ? get() : 1;
    return n < 1 ? 1 : (int)n; /* BLIS answers -1 when nothing was set: it then runs 1 thread */
  }
  case FC_BLAS_MKL: {
    get_int_fn get = (get_int_fn)symbol("MKL_Get_Max_Threads");
    return get ? get() : 1;
  }
  default:
    return 1;
  }
}

/* OpenBLAS's kernels for a CPU newer than the library. A DYNAMIC_ARCH build
 * chooses its kernel table from the CPU's family and model when it is loaded;
 * a model the release does not know gets the generic "Prescott" table (SSE3,
 * 2 doubles per instruction): Debian 12's OpenBLAS 0.3.21 on an Intel family 6
 * model 207 (Emerald Rapids) runs DGEMM 3-4x below its AVX-512 kernels. When
 * OpenBLAS answers "Prescott" (no CPU of the last fifteen years is one) on a
 * CPU that has AVX2 and FMA, the table is chosen again, before any BLAS call,
 * as SkylakeX (with AVX-512 F, CD, DQ, BW and VL) or Haswell (AVX2 and FMA):
 * OpenBLAS checks itself that the CPU and the operating system support what
 * it is forced to, and falls back when they do not. A user who set
 * OPENBLAS_CORETYPE (even to Prescott) is never overridden.
 * Returns 0 when nothing was done, 1 when the table was chosen again; `before`
 * and `after` receive the core names ("" when the library has none). */
int fc_openblas_core(char *before, int before_len, char *after, int after_len) {
  get_str_fn corename = (get_str_fn)symbol("openblas_get_corename");
  void (*quit)(void) = (void (*)(void))symbol("gotoblas_dynamic_quit");
  void (*init)(void) = (void (*)(void))symbol("gotoblas_dynamic_init");
  const char *user = getenv("OPENBLAS_CORETYPE");
  const char *target = NULL;
  copy_text(before, before_len, corename ? corename() : "");
  copy_text(after, after_len, corename ? corename() : "");
  if (!corename || !quit || !init || (user && user[0])) return 0;
  if (strcasecmp(corename(), "Prescott") != 0) return 0;
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512cd") && __builtin_cpu_supports("avx512dq") &&
      __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512vl"))
    target = "SkylakeX";
  else if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma"))
    target = "Haswell";
  if (!target) return 0;
  /* the variable only for the library's new choice; the user's environment is left as it was */
  if (setenv("OPENBLAS_CORETYPE", target, 1) != 0) return 0;
  quit();
  init();
  unsetenv("OPENBLAS_CORETYPE");
  copy_text(after, after_len, corename());
  return 1;
}

/* Ask the BLAS of `kind` to use `n` threads (nothing when it has no control). */
void fc_blas_set_threads(int kind, int n) {
  switch (kind) {
  case FC_BLAS_OPENBLAS: {
    set_int_fn set = (set_int_fn)symbol("openblas_set_num_threads");
    if (set) set(n);
    break;
  }
  case FC_BLAS_BLIS: {
    set_dim_fn set = (set_dim_fn)symbol("bli_thread_set_num_threads");
    if (set) set((int64_t)n);
    break;
  }
  case FC_BLAS_MKL: {
    set_int_fn set = (set_int_fn)symbol("MKL_Set_Num_Threads");
    if (set) set(n);
    break;
  }
  default:
    break;
  }
}
