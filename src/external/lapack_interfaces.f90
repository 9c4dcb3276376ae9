!> Explicit interfaces of the BLAS and LAPACK routines the code calls, in one
!> place (the libraries have no Fortran module): a wrong argument is then a
!> compile error, not a crash.
module lapack_interfaces
  use kinds, only: dp
  implicit none
  private
  public :: dpotrf, dpotrs, dpotri, dsyev, dsymv, dspmv, dgemv, dgemm, dtrsm, dtrsv, dsyrk, dtpsv, dpptri, dtpmv

  interface
    !> Cholesky factor of a symmetric positive definite matrix.
    subroutine dpotrf(uplo, n, a, lda, info)
      import :: dp
      character(len=1), intent(in) :: uplo
      integer, intent(in) :: n, lda
      real(dp), intent(inout) :: a(lda, *)
      integer, intent(out) :: info
    end subroutine dpotrf
    !> Solve A X = B with the Cholesky factor of dpotrf.
    subroutine dpotrs(uplo, n, nrhs, a, lda, b, ldb, info)
      import :: dp
      character(len=1), intent(in) :: uplo
      integer, intent(in) :: n, nrhs, lda, ldb
      real(dp), intent(in) :: a(lda, *)
      real(dp), intent(inout) :: b(ldb, *)
      integer, intent(out) :: info
    end subroutine dpotrs
    !> Inverse from the Cholesky factor of dpotrf.
    subroutine dpotri(uplo, n, a, lda, info)
      import :: dp
      character(len=1), intent(in) :: uplo
      integer, intent(in) :: n, lda
      real(dp), intent(inout) :: a(lda, *)
      integer, intent(out) :: info
    end subroutine dpotri
    !> Eigenvalues (and vectors) of a symmetric matrix.
    subroutine dsyev(jobz, uplo, n, a, lda, w, work, lwork, info)
      import :: dp
      character(len=1), intent(in) :: jobz, uplo
      integer, intent(in) :: n, lda, lwork
      real(dp), intent(inout) :: a(lda, *)
      real(dp), intent(out) :: w(*), work(*)
      integer, intent(out) :: info
    end subroutine dsyev
    !> y <- alpha A x + beta y, A symmetric (one triangle stored).
    subroutine dsymv(uplo, n, alpha, a, lda, x, incx, beta, y, incy)
      import :: dp
      character(len=1), intent(in) :: uplo
      integer, intent(in) :: n, lda, incx, incy
      real(dp), intent(in) :: alpha, beta, a(lda, *), x(*)
      real(dp), intent(inout) :: y(*)
    end subroutine dsymv
    !> y <- alpha A x + beta y, A symmetric in packed storage.
    subroutine dspmv(uplo, n, alpha, ap, x, incx, beta, y, incy)
      import :: dp
      character(len=1), intent(in) :: uplo
      integer, intent(in) :: n, incx, incy
      real(dp), intent(in) :: alpha, beta, ap(*), x(*)
      real(dp), intent(inout) :: y(*)
    end subroutine dspmv
    !> y <- alpha op(A) x + beta y.
    subroutine dgemv(trans, m, n, alpha, a, lda, x, incx, beta, y, incy)
      import :: dp
      character(len=1), intent(in) :: trans
      integer, intent(in) :: m, n, lda, incx, incy
      real(dp), intent(in) :: alpha, beta, a(lda, *), x(*)
      real(dp), intent(inout) :: y(*)
    end subroutine dgemv
    !> C <- alpha op(A) op(B) + beta C.
    subroutine dgemm(transa, transb, m, n, k, alpha, a, lda, b, ldb, beta, c, ldc)
      import :: dp
      character(len=1), intent(in) :: transa, transb
      integer, intent(in) :: m, n, k, lda, ldb, ldc
      real(dp), intent(in) :: alpha, beta, a(lda, *), b(ldb, *)
      real(dp), intent(inout) :: c(ldc, *)
    end subroutine dgemm
    !> B <- alpha op(A)^{-1} B (or B op(A)^{-1}), A triangular.
    subroutine dtrsm(side, uplo, transa, diag, m, n, alpha, a, lda, b, ldb)
      import :: dp
      character(len=1), intent(in) :: side, uplo, transa, diag
      integer, intent(in) :: m, n, lda, ldb
      real(dp), intent(in) :: alpha
      real(dp), intent(in) :: a(lda, *)
      real(dp), intent(inout) :: b(ldb, *)
    end subroutine dtrsm
    !> x <- op(A)^{-1} x, A triangular.
    subroutine dtrsv(uplo, trans, diag, n, a, lda, x, incx)
      import :: dp
      character(len=1), intent(in) :: uplo, trans, diag
      integer, intent(in) :: n, lda, incx
      real(dp), intent(in) :: a(lda, *)
      real(dp), intent(inout) :: x(*)
    end subroutine dtrsv
    !> C <- alpha op(A) op(A)^T + beta C, C symmetric (triangle `uplo`).
    subroutine dsyrk(uplo, trans, n, k, alpha, a, lda, beta, c, ldc)
      import :: dp
      character(len=1), intent(in) :: uplo, trans
      integer, intent(in) :: n, k, lda, ldc
      real(dp), intent(in) :: alpha, beta, a(lda, *)
      real(dp), intent(inout) :: c(ldc, *)
    end subroutine dsyrk
    !> x <- op(A)^{-1} x, A triangular in packed storage.
    subroutine dtpsv(uplo, trans, diag, n, ap, x, incx)
      import :: dp
      character(len=1), intent(in) :: uplo, trans, diag
      integer, intent(in) :: n, incx
      real(dp), intent(in) :: ap(*)
      real(dp), intent(inout) :: x(*)
    end subroutine dtpsv
    !> x <- op(A) x, A triangular in packed storage.
    subroutine dtpmv(uplo, trans, diag, n, ap, x, incx)
      import :: dp
      character(len=1), intent(in) :: uplo, trans, diag
      integer, intent(in) :: n, incx
      real(dp), intent(in) :: ap(*)
      real(dp), intent(inout) :: x(*)
    end subroutine dtpmv
    !> Inverse of a symmetric positive definite matrix from its packed
    !> Cholesky factor (dpptrf's, or dpotrf's triangle packed).
    subroutine dpptri(uplo, n, ap, info)
      import :: dp
      character(len=1), intent(in) :: uplo
      integer, intent(in) :: n
      real(dp), intent(inout) :: ap(*)
      integer, intent(out) :: info
    end subroutine dpptri
  end interface
end module lapack_interfaces
