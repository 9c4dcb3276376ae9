! Include in a .F90 test: 'HERE' expands to the file and line of the call.
#define HERE __FILE__, __LINE__
