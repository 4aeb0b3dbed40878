"""Session layer: what one message does, without ROS (screening, the stream identifier, the
divergence guard, health, the estimate file). Takes arrays and stamps; reads ROS-shaped messages
by duck typing only (:mod:`auv_ident.session.messages`)."""
