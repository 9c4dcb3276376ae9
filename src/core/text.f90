!> Numbers as text, the one place for it (i0 formatting), and lower case.
module text
  use kinds, only: dp, ip, i8
  implicit none
  private

  public :: str, lower_case, counted, ints_text, reals_text

  !> `n` in decimal, no blanks.
  interface str
    module procedure str_ip, str_i8
  end interface str

contains

  pure function str_i8(n) result(s)
    integer(i8), intent(in) :: n
    character(len=:), allocatable :: s
    character(len=24) :: buf
    write (buf, '(i0)') n
    s = trim(buf)
  end function str_i8

  pure function str_ip(n) result(s)
    integer(ip), intent(in) :: n
    character(len=:), allocatable :: s
    s = str_i8(int(n, i8))
  end function str_ip

  !> '1 node', '2 nodes': n and the noun, whose plural is `noun`//'s' unless
  !> `plural` is given ('1 matrix', '2 matrices').
  pure function counted(n, noun, plural) result(s)
    integer(ip), intent(in) :: n
    character(len=*), intent(in) :: noun
    character(len=*), intent(in), optional :: plural
    character(len=:), allocatable :: s
    if (n == 1) then
      s = str(n)//' '//noun
    else if (present(plural)) then
      s = str(n)//' '//plural
    else
      s = str(n)//' '//noun//'s'
    end if
  end function counted

  !> `s` with A-Z turned into a-z.
  pure function lower_case(s) result(r)
    character(len=*), intent(in) :: s
    character(len=len(s)) :: r
    integer :: i, c
    r = s
    do i = 1, len(s)
      c = iachar(s(i:i))
      if (c >= iachar('A') .and. c <= iachar('Z')) r(i:i) = achar(c + 32)
    end do
  end function lower_case

  !> The values of v separated by blanks (for messages).
  function ints_text(v) result(s)
    integer(ip), intent(in) :: v(:)
    character(len=:), allocatable :: s
    character(len=256) :: buf
    write (buf, '(*(i0,:," "))') v
    s = trim(buf)
  end function ints_text

  !> The values of v separated by blanks, 6 significant digits (for messages).
  function reals_text(v) result(s)
    real(dp), intent(in) :: v(:)
    character(len=:), allocatable :: s
    character(len=256) :: buf
    write (buf, '(*(g0.6,:," "))') v
    s = trim(buf)
  end function reals_text
end module text
