"""Models: definition as data, safe parsing, symbolic derivatives, compiled code, the zoo."""

from .codegen import CompiledModel as CompiledModel, compile_model as compile_model
from .spec import (Event as Event, Mode as Mode, Model as Model, Surface as Surface,
                   Switch as Switch, load_model as load_model, zoo_names as zoo_names)
from .control import with_discrete_control as with_discrete_control
from .iteration import iterate as iterate
from .chains import burridge_knopoff as burridge_knopoff
