/* The fields a simulation exports, declared once (C and C++ alike). From
 * this list come the C constants (tissue_field, tissue/tissue_c.h), the C++
 * tissue::Field and field_components / field_per_element
 * (tissue/simulation.hpp), and the Python methods of Simulation and Batch
 * (displacement(), positions(), ...). The engine's own store declares the
 * arrays behind them (the stored ones are written to the VTU files under
 * their own names: docs/design.md, "The store").
 *
 * TISSUE_FIELD(C name, C++ name, Python method, per, components, unit, what)
 * per: NODE or ELEMENT. A field's value is its place in the list. */
#ifndef TISSUE_FIELDS_H
#define TISSUE_FIELDS_H

#define TISSUE_FIELD_LIST(TISSUE_FIELD)                                                                \
  TISSUE_FIELD(DISPLACEMENT, Displacement, displacement, NODE, 3, "m", "displacement u")              \
  TISSUE_FIELD(POSITION, Position, positions, NODE, 3, "m", "position X + u")                          \
  TISSUE_FIELD(PRESSURE, Pressure, pressure, NODE, 1, "Pa", "IANP nodal pressure")                    \
  TISSUE_FIELD(INTERNAL_FORCE, InternalForce, internal_force, NODE, 3, "N",                            \
               "internal nodal force less the applied load (set_loads)")                               \
  TISSUE_FIELD(JACOBIAN, Jacobian, jacobian, ELEMENT, 1, "1", "J = det F (last computed value)")

#endif
