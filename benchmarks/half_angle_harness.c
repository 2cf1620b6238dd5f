/* fk_dq, pose_jacobian_dq, g_dq, tau_dq of lwr4 with the half angles by libm (old_*) against
 * the sincos kernel (new_*), both builds linked into this one binary and timed in interleaved
 * rounds (docs/latency.md, "Half angles through the kernel", gives the build commands: each
 * generated lwr4.c compiled -O3 -march=native, its four functions renamed by objcopy).
 * argv[1] = rounds (21); prints the median and minimum ns per call of each. */
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include <math.h>
void old_fk_dq(const double*, double*); void new_fk_dq(const double*, double*);
void old_pj_dq(const double*, double*); void new_pj_dq(const double*, double*);
void old_g_dq(const double*, double*); void new_g_dq(const double*, double*);
void old_tau_dq(const double*, const double*, const double*, double*); void new_tau_dq(const double*, const double*, const double*, double*);
static double now(void){struct timespec t; clock_gettime(CLOCK_MONOTONIC,&t); return t.tv_sec*1e9+t.tv_nsec;}
#define N 1024
#define REPS 200
static double Q[N][7], QD[N][7], QDD[N][7], OUT[64*8];
static volatile double sink;
static int cmp(const void*a,const void*b){double x=*(const double*)a,y=*(const double*)b;return (x>y)-(x<y);}
/* one timing: ns per single call over N configurations x REPS */
#define TIME1(call) ({ double t0=now(); for(int r=0;r<REPS;++r) for(int i=0;i<N;++i){ call; sink+=OUT[0]; } (now()-t0)/(REPS*(double)N); })
int main(int argc, char**argv){
  int rounds = argc>1?atoi(argv[1]):21;
  srand(1); for(int i=0;i<N;++i) for(int k=0;k<7;++k){Q[i][k]=(rand()/(double)RAND_MAX*2-1)*2.9; QD[i][k]=rand()/(double)RAND_MAX-0.5; QDD[i][k]=rand()/(double)RAND_MAX-0.5;}
  /* agreement check of the two builds */
  double worst=0, o[8], n[8];
  for(int i=0;i<N;++i){ old_fk_dq(Q[i],o); new_fk_dq(Q[i],n); for(int k=0;k<8;++k) worst=fmax(worst,fabs(o[k]-n[k])); }
  printf("fk_dq max |old-new| %.3g\n", worst);
  /* latency: each call's angles depend on the previous call's pose */
  {
    double a[64], b[64]; double qq[7]={0};
    for(int r=0;r<rounds;++r){
      for(int v=0; v<2; ++v){
        double t0=now();
        for(int rep=0;rep<REPS;++rep) for(int i=0;i<N;++i){ for(int k=0;k<7;++k) qq[k]=Q[i][k]+1e-300*OUT[k]; if(v) new_fk_dq(qq,OUT); else old_fk_dq(qq,OUT); }
        (v?b:a)[r]=(now()-t0)/(REPS*(double)N);
      }
    }
    qsort(a,rounds,sizeof(double),cmp); qsort(b,rounds,sizeof(double),cmp);
    printf("%-18s libm %.2f ns  kernel %.2f ns  (dependent calls, median of %d interleaved; min %.2f / %.2f)  ratio %.2f\n", "fk_dq latency", a[rounds/2], b[rounds/2], rounds, a[0], b[0], a[rounds/2]/b[rounds/2]);
  }
  const char* names[4]={"fk_dq","pose_jacobian_dq","g_dq","tau_dq"};
  for(int f=0;f<4;++f){
    double *a=malloc(rounds*sizeof(double)), *b=malloc(rounds*sizeof(double));
    for(int r=0;r<rounds;++r){
      switch(f){
      case 0: a[r]=TIME1(old_fk_dq(Q[i],OUT)); b[r]=TIME1(new_fk_dq(Q[i],OUT)); break;
      case 1: a[r]=TIME1(old_pj_dq(Q[i],OUT)); b[r]=TIME1(new_pj_dq(Q[i],OUT)); break;
      case 2: a[r]=TIME1(old_g_dq(Q[i],OUT)); b[r]=TIME1(new_g_dq(Q[i],OUT)); break;
      case 3: a[r]=TIME1(old_tau_dq(Q[i],QD[i],QDD[i],OUT)); b[r]=TIME1(new_tau_dq(Q[i],QD[i],QDD[i],OUT)); break;
      }
    }
    qsort(a,rounds,sizeof(double),cmp); qsort(b,rounds,sizeof(double),cmp);
    printf("%-18s libm %.2f ns  kernel %.2f ns  (median of %d interleaved; min %.2f / %.2f)  ratio %.2f\n", names[f], a[rounds/2], b[rounds/2], rounds, a[0], b[0], a[rounds/2]/b[rounds/2]);
  }
  return 0;
}
